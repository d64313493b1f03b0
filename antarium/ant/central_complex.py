"""Stone et al. 2017's central complex (CX) for path integration: a rate model in pure numpy.

Layers (rates in [0, 1]): TL2 (16) and CL1 (16) carry the compass heading, TB1 (8) is the ring attractor of the
protocerebral bridge (CL1 excitation, TB1-TB1 inhibition with a cosine profile), TN2 (2) the speed seen at
+-45 deg of the body axis, CPU4 (16 = 2 x 8 columns) the integrating memory, Pontine (16) and CPU1 (16 = 2 x 8) the
steering layer, whose two halves sum to the left and right motor drive. This is the paper's "Pontine" model
(holonomic-free, speed by TN2 only): CPU4 += gain * clip(TN2 - TB1, 0, 1) - leak_bias * gain, clipped to [0, 1];
CPU1 = sigmoid(0.5 CPU4 (shifted one column) - 0.5 Pontine - TB1). Parameters, their values and the noise
(Gaussian, sd 0.1 on every rate) are the paper's; `leak` (per step, 0 in the paper) lets the memory decay
towards 0.5.

The CPU4 memory can be stored and restored (vector memory, Mitchell 2019 section 2.5): `memory` / `restore`.
Columns: TB1 column j prefers heading j * 45 deg (CCW); CPU4[0] integrates speed seen at +45 deg (left),
CPU4[1] at -45 deg (right).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import expit

N_COLUMNS = 8
PREFS = np.arange(N_COLUMNS) * (math.tau / N_COLUMNS)


@dataclass(frozen=True)
class CXParams:
    """Stone et al. 2017 (rate model with Pontine cells): tuned sigmoid slopes and biases, noise, memory gain."""

    noise: float = 0.1
    tl2_slope: float = 6.8
    tl2_bias: float = 3.0
    cl1_slope: float = 3.0
    cl1_bias: float = -0.5
    tb1_slope: float = 5.0
    tb1_bias: float = 0.0
    prop_cl1: float = 0.667           # share of TB1 input from CL1 (the rest: TB1-TB1 inhibition)
    cpu4_slope: float = 5.0
    cpu4_bias: float = 2.5
    cpu4_gain: float = 0.0025         # memory accumulation per step (0.005 halved in the Pontine model)
    cpu4_decay_bias: float = 0.125    # constant decrement per step, in units of cpu4_gain
    leak: float = 0.0                 # extra decay of (memory - 0.5) per step (0: the paper's perfect memory)
    pontine_slope: float = 5.0
    pontine_bias: float = 2.5
    cpu1_slope: float = 7.5
    cpu1_bias: float = -1.0
    seed: int = 0

    def __post_init__(self) -> None:
        if self.noise < 0 or not 0 <= self.leak < 1 or self.cpu4_gain <= 0:
            raise ValueError(f"CX noise must be >= 0, leak in [0, 1), cpu4_gain > 0; got {self.noise!r}, "
                             f"{self.leak!r}, {self.cpu4_gain!r}")
        if not 0 < self.prop_cl1 <= 1:
            raise ValueError(f"CX prop_cl1 must be in (0, 1], got {self.prop_cl1!r}")


def _tb1_tb1() -> np.ndarray:
    """(8, 8) TB1-TB1 inhibition: (1 - cos(column difference)) / 2."""
    diff = PREFS[:, None] - PREFS[None, :]
    return (1.0 - np.cos(diff)) / 2.0


_W_TB1_TB1 = _tb1_tb1()
#: Pontine cell feeding each CPU1 (half, column): half 0 column j <- CPU4 right column (j + 3) % 8, half 1 <- left
#: column (j + 5) % 8 (Stone 2017, W_pontin_CPU1)
_PONTINE = np.concatenate([8 + (np.arange(8) + 3) % 8, (np.arange(8) + 5) % 8])
#: CPU4 cell feeding each CPU1: half 0 column j <- right column j - 1, half 1 <- left column j + 1
_CPU4_TO_CPU1 = np.concatenate([8 + (np.arange(8) - 1) % 8, (np.arange(8) + 1) % 8])


class CentralComplex:
    """One CX: `step(heading, speed)` updates TB1 and CPU4 and returns the motor output (> 0: turn left)."""

    def __init__(self, params: CXParams | None = None) -> None:
        self.params = params or CXParams()
        self.rng = np.random.default_rng(self.params.seed)
        self.reset()

    def reset(self) -> None:
        self.tb1 = np.zeros(N_COLUMNS)
        self.cpu4 = np.full(2 * N_COLUMNS, 0.5)     # the memory (CPU4 "calcium"), not its sigmoid output
        self.cpu1 = np.zeros(2 * N_COLUMNS)

    def _sig(self, v: np.ndarray, slope: float, bias: float) -> np.ndarray:
        out = expit(v * slope - bias)
        if self.params.noise > 0:
            out = out + self.rng.normal(0.0, self.params.noise, out.shape)
        return np.clip(out, 0.0, 1.0)

    def compass(self, heading: float) -> np.ndarray:
        """TL2 -> CL1 -> TB1 for a heading (rad); updates and returns TB1 (8,)."""
        p = self.params
        tl2 = self._sig(np.cos(heading - np.tile(PREFS, 2)), p.tl2_slope, p.tl2_bias)
        cl1 = self._sig(-tl2, p.cl1_slope, p.cl1_bias)
        drive = p.prop_cl1 * (cl1[:N_COLUMNS] + cl1[N_COLUMNS:]) - (1 - p.prop_cl1) * _W_TB1_TB1 @ self.tb1
        self.tb1 = self._sig(drive, p.tb1_slope, p.tb1_bias)
        return self.tb1

    def integrate(self, speed: float) -> None:
        """CPU4 memory update for forward speed `speed` (0..1 of full speed) along the current TB1 heading."""
        p = self.params
        tn2 = np.full(2, speed * math.cos(math.pi / 4))
        if p.noise > 0:
            tn2 = tn2 + self.rng.normal(0.0, p.noise, 2)
        tn2 = np.clip(tn2, 0.0, 1.0)
        update = np.clip(np.repeat(tn2, N_COLUMNS) - np.tile(self.tb1, 2), 0.0, 1.0) * p.cpu4_gain
        mem = self.cpu4 + update - p.cpu4_decay_bias * p.cpu4_gain
        mem -= p.leak * (mem - 0.5)
        self.cpu4 = np.clip(mem, 0.0, 1.0)

    def steering(self, extra: np.ndarray | None = None, k: float = 1.0) -> np.ndarray:
        """CPU1 (16,) from the memory and TB1; `extra` (16,), laid out as CPU4, joins the CPU4 input with weight
        1 - k, CPU4 with weight k (Zhang's CXMB, Mitchell 2019 eq. 4); no extra: Stone's CX."""
        p = self.params
        cpu4 = self._sig(self.cpu4, p.cpu4_slope, p.cpu4_bias)
        pontine = self._sig(cpu4, p.pontine_slope, p.pontine_bias)
        memory = 0.5 * cpu4[_CPU4_TO_CPU1]
        if extra is not None:
            memory = k * memory + (1.0 - k) * 0.5 * np.asarray(extra, np.float64)[_CPU4_TO_CPU1]
        drive = memory - 0.5 * pontine[_PONTINE] - np.tile(self.tb1, 2)
        self.cpu1 = self._sig(drive, p.cpu1_slope, p.cpu1_bias)
        return self.cpu1

    def motor(self) -> float:
        """Left minus right motor drive from CPU1 (> 0: turn left), as Stone's 0.25 * (sum half 0 - sum half 1)."""
        return 0.25 * float(self.cpu1[:N_COLUMNS].sum() - self.cpu1[N_COLUMNS:].sum())

    def step(self, heading: float, speed: float) -> float:
        self.compass(heading)
        self.integrate(speed)
        self.steering()
        return self.motor()

    def memory(self) -> np.ndarray:
        """A copy of the CPU4 memory (16,), for vector memory."""
        return self.cpu4.copy()

    def restore(self, memory: np.ndarray) -> None:
        m = np.asarray(memory, np.float64)
        if m.shape != (2 * N_COLUMNS,) or not np.all(np.isfinite(m)):
            raise ValueError(f"CPU4 memory must be ({2 * N_COLUMNS},) finite floats, got shape {m.shape}")
        self.cpu4 = np.clip(m, 0.0, 1.0)

    def home_vector(self) -> tuple[float, float]:
        """(direction rad, strength) of the memory's population vector (shifted CPU4 halves): it points from the
        nest to the ant (the outbound vector); home lies opposite."""
        left = np.roll(self.cpu4[:N_COLUMNS], 1)
        right = np.roll(self.cpu4[N_COLUMNS:], -1)
        z = ((left + right) * np.exp(1j * PREFS)).sum()
        return float(np.angle(z)), float(abs(z))
