"""Stone et al. 2017's central complex (CX) for path integration: a rate model in pure numpy.

Layers (rates in [0, 1]): TL2 (16) and CL1 (16) carry the compass heading, TB1 (8) is the ring attractor of the
protocerebral bridge (CL1 excitation, TB1-TB1 inhibition with a cosine profile), TN2 (2) the speed seen at
+-45 deg of the body axis, CPU4 (16 = 2 x 8 columns) the integrating memory, Pontine (16) and CPU1 (16 = 2 x 8) the
steering layer, whose two halves sum to the left and right motor drive. This is the paper's "Pontine" model
(holonomic-free, speed by TN2 only): CPU4 += gain * clip(TN2 - TB1, 0, 1) - cpu4_decay_bias * gain, clipped to [0, 1];
CPU1 = sigmoid(0.5 CPU4 (shifted one column) - 0.5 Pontine - TB1). Parameters, their values and the noise
(Gaussian, sd 0.1 on every rate) are the paper's; `leak` (per step, 0 in the paper) lets the memory decay
towards 0.5.

The CPU4 memory can be stored and restored (vector memory, Mitchell 2019 section 2.5): `memory` / `restore`.
Columns: TB1 column j prefers heading j * 45 deg (CCW); CPU4[0] integrates speed seen at +45 deg (left),
CPU4[1] at -45 deg (right).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, fields

import numpy as np

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
        bad = [f"{f.name}={getattr(self, f.name)!r}" for f in fields(self)
               if f.name != "seed" and not math.isfinite(getattr(self, f.name))]
        if bad:  # NaN passed the range checks below: a NaN noise left the CX steering 0, a NaN gain no memory
            raise ValueError(f"CX parameters must be finite numbers, got {', '.join(bad)}")
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


_BLOCK = 4096                     # noise values drawn at once (the same stream as drawing them one rate at a time)


@functools.cache
def _kernels():
    """The compiled loops (numba), imported on first use."""
    from antarium.ant import cx_kernels

    return cx_kernels


def param_vector(params: CXParams) -> np.ndarray:
    """The `CXParams` fields, in declaration order, as float64 (the compiled kernels' parameter layout)."""
    return np.array([float(getattr(params, f.name)) for f in fields(params)])


class CentralComplex:
    """One CX: `step(heading, speed)` updates TB1 and CPU4 and returns the motor output (> 0: turn left).

    Every rate is clip(sigmoid(v * slope - bias) + N(0, noise), 0, 1); the steps run as compiled kernels
    (`cx_kernels`) on preallocated arrays, the noise drawn from `rng` in blocks in the order of the rates."""

    def __init__(self, params: CXParams | None = None) -> None:
        self.params = params or CXParams()
        self.rng = np.random.default_rng(self.params.seed)
        self._prm = param_vector(self.params)
        self._noise = np.empty(0)
        self._at = 0
        self._zeros = np.zeros(3 * 2 * N_COLUMNS)
        self._no_extra = np.zeros(2 * N_COLUMNS)
        self.reset()

    def reset(self) -> None:
        self.tb1 = np.zeros(N_COLUMNS)
        self.cpu4 = np.full(2 * N_COLUMNS, 0.5)     # the memory (CPU4 "calcium"), not its sigmoid output
        self.cpu1 = np.zeros(2 * N_COLUMNS)

    def _draw(self, n: int) -> np.ndarray:
        """The next n noise values (zeros without noise)."""
        if self.params.noise <= 0:
            return self._zeros[:n]
        if self._at + n > self._noise.size:
            self._noise = np.concatenate([self._noise[self._at:], self.rng.normal(0.0, self.params.noise, _BLOCK)])
            self._at = 0
        self._at += n
        return self._noise[self._at - n:self._at]

    def compass(self, heading: float) -> np.ndarray:
        """TL2 -> CL1 -> TB1 for a heading (rad); updates and returns TB1 (8,). TL2 = rate(cos(heading - pref)),
        CL1 = rate(-TL2), TB1 = rate(prop_cl1 (CL1 left + right) - (1 - prop_cl1) W_TB1_TB1 TB1)."""
        _kernels().cx_compass(float(heading), self.tb1, _W_TB1_TB1, PREFS, self._prm, self._draw(5 * N_COLUMNS))
        return self.tb1

    def integrate(self, speed: float) -> None:
        """CPU4 memory update for forward speed `speed` (0..1 of full speed) along the current TB1 heading:
        TN2 = clip(speed cos 45 deg + noise), CPU4 += gain clip(TN2 - TB1, 0, 1) - decay_bias gain, leak, clip."""
        _kernels().cx_integrate(float(speed), self.tb1, self.cpu4, self._prm, self._draw(2))

    def steering(self, extra: np.ndarray | None = None, k: float = 1.0) -> np.ndarray:
        """CPU1 (16,) from the memory and TB1; `extra` (16,), laid out as CPU4, joins with weight 1 - k all that
        CPU1 gets from CPU4 (directly and through the Pontine cells), which gets weight k (Zhang's CXMB, Mitchell
        2019 eq. 4: k = 0 steers by `extra` alone); no extra: Stone's CX. Anything else is refused (ValueError).
        CPU1 = rate(k (0.5 CPU4out (shifted) - 0.5 Pontine) + (1 - k) 0.5 (extra (shifted) - extra (Pontine's
        column)) - TB1): `extra` centred as CPU4's input is, so that a flat input adds no turn,
        CPU4out = rate(CPU4), Pontine = rate(CPU4out)."""
        use = extra is not None
        e = np.asarray(extra, np.float64) if use else self._no_extra
        if use and (e.shape != (2 * N_COLUMNS,) or not np.isfinite(e).all()) or not 0.0 <= k <= 1.0:
            # the compiled kernel does not check bounds: a shorter `extra` was read past its end
            raise ValueError(f"CPU1's extra input must be ({2 * N_COLUMNS},) finite values and k in [0, 1], got "
                             f"shape {e.shape} and k={k!r}")
        _kernels().cx_steering(self.tb1, self.cpu4, self.cpu1, e, float(k), use, _CPU4_TO_CPU1, _PONTINE, self._prm,
                            self._draw(6 * N_COLUMNS))
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
        """Set the CPU4 memory to `memory` (16,) rates in [0, 1] (as `memory` gives them); anything else is
        refused (ValueError) and the memory kept."""
        m = np.asarray(memory, np.float64)
        if m.shape != (2 * N_COLUMNS,) or not np.all((m >= 0.0) & (m <= 1.0)):
            raise ValueError(f"CPU4 memory must be ({2 * N_COLUMNS},) rates in [0, 1], got shape {m.shape} with "
                             f"values {np.min(m, initial=np.inf)} to {np.max(m, initial=-np.inf)}")
        self.cpu4 = m.copy()

    def home_vector(self) -> tuple[float, float]:
        """(direction rad, strength) of the memory's population vector (shifted CPU4 halves): it points from the
        nest to the ant (the outbound vector); home lies opposite."""
        return _kernels().cx_home_vector(self.cpu4, PREFS)
