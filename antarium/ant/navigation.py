"""Central-complex navigation models of the virtual ant: Stone et al. 2017's path integration (CX), Zhang's
eight-MBON CXMB (Mitchell 2019, section 2.5) and Mitchell's One Ring (CX + MB + optic-flow avoidance at CPU1).

These models decide from `Senses` (what `VirtualAnt.sense()` gives: the view, the compass reading, the distance
walked since the last decision as the loop integrated it from the ball), not from the view alone. Per decision:
the compass heading sets TB1, the distance walked (/ `speed_scale`, clipped to 1) drives TN2 and CPU4 integrates;
CPU1 steers: turn = clip(turn_gain * motor, +-max_turn) rad, forward `step` m. `observe(senses)` integrates
without steering (an outbound walk driven from outside). Without a compass cue `decide` raises NoSkyCueError.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from antarium.ant.central_complex import N_COLUMNS, PREFS, CentralComplex, CXParams
from antarium.ant.command import Command, clip_turn
from antarium.ant.compass import COMPASSES, CompassReading, NoSkyCueError
from antarium.ant.mushroom_body import MBON, KenyonCells


@dataclass(frozen=True, slots=True)
class Senses:
    """One decision's input: view (an eye `View`), compass (`CompassReading`), travelled (m since the last
    decision, from the loop's pose, i.e. the ball), leds (the (N, 2) uint16 frame the dome shows)."""

    view: object
    compass: CompassReading
    travelled: float
    leds: np.ndarray | None = None
    yaw: float = 0.0


@dataclass(frozen=True)
class CXModelParams:
    """Stone 2017's CX (the `CXParams` fields) and how the virtual ant walks with it."""

    compass: str = "sky"              # sky: from the dome's polarised UV pixels; ideal: the true heading
    step: float = 0.01                # m per decision
    speed_scale: float = 0.02         # m per decision that TN2 reads as full speed (1)
    turn_gain: float = 1.0            # rad per unit motor output
    max_turn: float = 0.5             # rad per decision
    noise: float = 0.1
    cpu4_gain: float = 0.0025
    leak: float = 0.0
    avoid: bool = False               # add the optic-flow collision avoidance's turn after CPU1
    flow_method: str = "filter"       # filter | foe (antarium.ant.optic_flow)
    flow_gain: float = 0.15           # rad of avoidance turn at full imbalance (0.5 out-turned the CX in clutter)
    seed: int = 0

    def __post_init__(self) -> None:
        if self.compass not in COMPASSES:
            raise ValueError(f"compass {self.compass!r} not known; allowed: {', '.join(COMPASSES)}")
        if self.step <= 0 or self.speed_scale <= 0 or self.max_turn <= 0:
            raise ValueError("CX step, speed_scale and max_turn must be > 0")
        from antarium.ant.optic_flow import METHODS

        if self.flow_method not in METHODS or not self.flow_gain > 0:
            raise ValueError(f"CX flow_method must be one of {', '.join(METHODS)} and flow_gain > 0 rad, got "
                             f"{self.flow_method!r} and {self.flow_gain!r}")

    def cx(self) -> CXParams:
        return CXParams(noise=self.noise, cpu4_gain=self.cpu4_gain, leak=self.leak, seed=self.seed)


class CXModel:
    """Path integration: integrates while walking, steers home by CPU1 (Stone et al. 2017)."""

    kind = "cx"
    learns_continuously = False
    uses_senses = True
    needs_view = False

    def __init__(self, n_pn: int, params: CXModelParams | None = None):
        self.params = params or CXModelParams()
        self.n_pn = n_pn
        self.cx = CentralComplex(self.params.cx())
        self.learned_views = 0
        self._ofca = None

    def avoidance(self, senses: Senses) -> tuple[float, dict[str, float]]:
        """The optic-flow turn (rad, > 0 left) since the previous call (the dome's flow set up on first use)."""
        if self._ofca is None:
            from antarium.ant.optic_flow import CollisionAvoidance, FlowParams, OpticFlow
            from antarium.geometry import load_dome

            flow = OpticFlow.from_dome(load_dome(), FlowParams(method=self.params.flow_method,
                                                               gain=self.params.flow_gain))
            self._ofca = CollisionAvoidance(flow)
        return self._ofca.turn(senses.leds, senses.yaw, senses.travelled)

    def carried(self) -> None:
        """The ant was put down elsewhere: no optic flow from the jump."""
        if self._ofca is not None:
            self._ofca.forget()

    def reset(self) -> None:
        """Nothing: the memory is kept between runs (store / restore it for vector memory)."""

    def home_memory(self) -> np.ndarray:
        return self.cx.memory()

    def restore(self, memory: np.ndarray) -> None:
        self.cx.restore(memory)

    def observe(self, senses: Senses) -> dict[str, float]:
        """Compass and integration of one decision's walk; returns the trace."""
        if not senses.compass.cue:
            raise NoSkyCueError(f"the {self.params.compass} compass has no cue: {senses.compass.why}")
        speed = min(1.0, max(0.0, senses.travelled / self.params.speed_scale))
        self.cx.compass(senses.compass.heading)
        self.cx.integrate(speed)
        direction, strength = self.cx.home_vector()
        return {"compass": senses.compass.heading, "speed": speed, "memory_direction": direction,
                "memory_strength": strength}

    def _extra(self, senses: Senses) -> tuple[np.ndarray | None, float, dict[str, float]]:
        """CPU1's extra memory input (16,) or None, CPU4's weight k against it, the trace; the trace holds
        "flow_turn" when the optic flow went into the extra input (then `decide` adds no avoidance turn)."""
        return None, 1.0, {}

    def decide(self, senses: Senses) -> Command:
        trace = self.observe(senses)
        extra, k, more = self._extra(senses)
        self.cx.steering(extra, k)
        motor = self.cx.motor()
        turn = clip_turn(self.params.turn_gain * motor, self.params.max_turn)
        if self.params.avoid and "flow_turn" not in more:  # the flow is read once per decision
            flow_turn, flow_trace = self.avoidance(senses)
            more = {**more, **flow_trace}
            turn = clip_turn(turn + flow_turn, self.params.max_turn)
        return Command(self.params.step, turn, {**trace, **more, "motor": motor})


@dataclass(frozen=True)
class CXMBParams(CXModelParams):
    """CXMB: the CX with one KC -> MBON array per TB1 direction; k weighs CPU4 against the MBONs (0.8, Zhang)."""

    k: float = 0.8
    n_kc: int = 20_000
    pn_per_kc: int = 10
    kappa: float = 0.01

    def __post_init__(self) -> None:
        CXModelParams.__post_init__(self)
        if not 0.0 <= self.k <= 1.0:
            raise ValueError(f"CXMB k must be in [0, 1], got {self.k!r}")


#: CPU4 cell (16,) each MBON column feeds: both halves, turned by half the ring (np.tile(np.roll(m, 4), 2))
_MBON_TO_CPU4 = (np.arange(2 * N_COLUMNS) - N_COLUMNS // 2) % N_COLUMNS


class CXMBModel(CXModel):
    """Zhang's eight-MBON model: learning writes to the MBON of the current TB1 heading; the normalised inverse
    MBON responses join CPU4 at CPU1 with weight 1 - k (Mitchell 2019, equations 2-4)."""

    kind = "cxmb"
    needs_view = True

    def __init__(self, n_pn: int, params: CXMBParams | None = None, mbons: dict[str, MBON] | None = None):
        params = params or CXMBParams()
        super().__init__(n_pn, params)
        self.kc = KenyonCells(n_pn, params.n_kc, params.pn_per_kc, params.kappa, params.seed)
        self.mbons = mbons or {f"tb1_{j}": MBON(params.n_kc) for j in range(N_COLUMNS)}
        self.learning = False      # True: learn every view into the current TB1 direction's MBON (first trip)
        self.use_mbons = True      # False: steer by the CX alone (the comparison trip)

    def tb1_column(self) -> int:
        """The TB1 column of the current heading (TB1 is least active at the heading's column)."""
        z = ((1.0 - self.cx.tb1) * np.exp(1j * PREFS)).sum()
        return int(round(np.angle(z) / (math.tau / N_COLUMNS))) % N_COLUMNS

    def learn(self, view) -> None:
        """Learn `view` into the MBON of the current TB1 heading."""
        self.mbons[f"tb1_{self.tb1_column()}"].learn(self.kc.active(view.pns((0.0,))))
        self.learned_views += 1

    def responses(self, view) -> np.ndarray:
        """The eight MBONs' responses M_i (novelty, 1 = novel) to `view`, in TB1 column order: each MBON's
        undepressed share of the active KCs' synapses (`MBON.novelty`), in one compiled pass (`KenyonCells.novelty`)."""
        return self.kc.novelty(view.pns((0.0,)), [self.mbons[f"tb1_{j}"] for j in range(N_COLUMNS)])[0]

    def mbon_input(self, view) -> tuple[np.ndarray, dict[str, float]]:
        """Equations 2-3 laid out as CPU4 (16,): the normalised inverse MBON responses. MBON column j says "head
        towards j"; CPU4 holds the outbound vector, which CPU1 steers away from, so the columns turn by 4."""
        m = self.responses(view)
        inverse = 1.0 - m / max(m.sum(), 1e-12)
        return inverse[_MBON_TO_CPU4], {"mbon_best": float(np.argmin(m)), "mbon_contrast": float(m.max() - m.min())}

    def _extra(self, senses: Senses):
        if self.learning:
            self.learn(senses.view)
            return None, 1.0, {"learning_column": float(self.tb1_column())}
        if not self.use_mbons:
            return None, 1.0, {}
        extra, trace = self.mbon_input(senses.view)
        return extra, self.params.k, trace


@dataclass(frozen=True)
class OneRingParams(CXMBParams):
    """One Ring (Mitchell 2019): CPU4, the MBONs and the optic flow join at CPU1 with weights k_cx, k_mb, k_of
    (CXMB's k is not used and must keep its default)."""

    k_cx: float = 0.6
    k_mb: float = 0.2
    k_of: float = 0.2
    flow_swing: float = math.pi / 2   # rad off the heading the flow's bump points to at full imbalance

    def __post_init__(self) -> None:
        CXMBParams.__post_init__(self)
        if self.k != CXMBParams.k:  # inherited from CXMB, unused: One Ring weighs its three inputs itself
            raise ValueError(f"One Ring does not use CXMB's k (got {self.k!r}; allowed: its default {CXMBParams.k}); "
                             f"weigh CPU4, the MBONs and the optic flow with k_cx, k_mb, k_of")
        w = (self.k_cx, self.k_mb, self.k_of)
        if min(w) < 0 or not math.isclose(sum(w), 1.0, abs_tol=1e-9):
            raise ValueError(f"One Ring weights k_cx, k_mb, k_of must be >= 0 and sum to 1, got {w}")
        if not 0.0 <= self.flow_swing <= math.pi:
            raise ValueError(f"One Ring flow_swing must be in [0, pi] rad, got {self.flow_swing!r}")


_PREFS_CPU4 = np.tile(PREFS, 2)  # each CPU4 cell's preferred direction (both halves)


def heading_bump(desired: float, height: float) -> np.ndarray:
    """(16,) float64: a desired heading `desired` (rad) as CPU1's memory input, like the MBONs': a cosine bump of
    `height` (0..1) about 0.5, peaking opposite `desired`, as CPU1 steers away from the vector CPU4 holds."""
    return 0.5 + 0.5 * height * np.cos(_PREFS_CPU4 - (desired + math.pi))


class OneRingModel(CXMBModel):
    """Path integration, visual memory and collision avoidance combined at CPU1. The optic-flow avoidance becomes
    a desired heading coded on the ring (`heading_bump`): away from the side with more flow, up to `flow_swing`
    off the compass heading, and as high as the imbalance (its turn's share of `flow_gain`; flat without flow)."""

    kind = "one_ring"

    def _extra(self, senses: Senses):
        if self.learning or not self.use_mbons:  # the CX alone, as CXMB's (the first trip, the comparison trip)
            return super()._extra(senses)
        p = self.params
        mb, trace = self.mbon_input(senses.view)
        flow_turn, flow_trace = self.avoidance(senses)
        share = flow_turn / p.flow_gain  # -1 (all flow on the left: turn right) .. 1
        of = heading_bump(senses.compass.heading + share * p.flow_swing, min(1.0, abs(share)))
        rest = p.k_mb + p.k_of
        extra = (p.k_mb * mb + p.k_of * of) / rest if rest > 0 else None
        return extra, p.k_cx, {**trace, **flow_trace}


NAVIGATION_MODELS = {"cx": (CXModel, CXModelParams), "cxmb": (CXMBModel, CXMBParams),
                     "one_ring": (OneRingModel, OneRingParams)}
