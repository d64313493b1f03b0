"""Navigation models of the virtual ant: Ardin et al. 2016, Antcar (Gattaux et al. 2025), perfect memory.

Every model learns `View`s (`learn`) and turns the current view into a `Command` (`decide`): a step along the
body axis (metres; negative = walking backward) and a turn (radians, counter-clockwise), with the model's
internal signals (familiarities, motivation) in `Command.trace` for the trial log.
"""

from __future__ import annotations

import math
import typing
from dataclasses import asdict, dataclass, fields

import numpy as np

from antarium.ant.command import Command
from antarium.ant.eye import View
from antarium.ant.mushroom_body import MBON, KenyonCells, check_wiring
from antarium.ant.navigation import NAVIGATION_MODELS
from antarium.core.numbers import check_number


def oscillation_angles(amplitude: float, step: float, phase: float = 0.0) -> np.ndarray:
    """In-silico oscillation theta_c(n) = A sin(n * 2 pi / (N + 1)), n = 0..N, N = 2A / step (Antcar eq. 6).

    One full oscillation cycle per learned view in N + 1 samples (A = 45 deg, step = 5 deg: 19 rotations
    spanning +-A), as Antcar's "single oscillation cycle per image". `phase` (rad) is the oscillation's centre
    relative to the direction of travel: pi learns the views looking back along the route (homing).
    Returns (N + 1,) float64 radians, relative to the centre.
    """
    if amplitude <= 0 or step <= 0:
        raise ValueError(f"oscillation amplitude and step must be > 0 rad, got {amplitude}, {step}")
    n_steps = int(round(2 * amplitude / step))
    n = np.arange(n_steps + 1)
    return amplitude * np.sin(n * math.tau / (n_steps + 1))


def _check_ranges(model: str, params, rules: dict[str, tuple[bool, str]]) -> None:
    """One ValueError for the first parameter whose rule (holds, what is allowed) does not hold (NaN never does)."""
    for key, (holds, allowed) in rules.items():
        if not holds:
            raise ValueError(f"{model} {key} must be {allowed}, got {getattr(params, key)!r}")


def _check_scan(model: str, params) -> None:
    """The scanning models' scan (half range >= 0 deg, step > 0 deg) and step (> 0 m per decision)."""
    _check_ranges(model, params, {"scan_deg": (params.scan_deg >= 0, ">= 0 deg"),
                                  "scan_step_deg": (params.scan_step_deg > 0, "> 0 deg"),
                                  "step": (params.step > 0, "> 0 m")})


def _scan_angles(half_range: float, step: float) -> np.ndarray:
    n = int(round(half_range / step))
    return np.arange(-n, n + 1) * step


def _best_angle(angles: np.ndarray, cost: np.ndarray) -> int:
    """Index of the lowest cost among `angles` (ascending). Among ties, the middle of the run of tied neighbours
    that holds the smallest turn (of its two middles, the smaller turn): a plateau of fully familiar directions
    is centred on the route, and its edge nearest straight ahead is not."""
    tied = cost <= cost.min() + 1e-12
    best = np.flatnonzero(tied)
    lo = hi = int(best[np.argmin(np.abs(angles[best]))])
    while lo > 0 and tied[lo - 1]:
        lo -= 1
    while hi < len(tied) - 1 and tied[hi + 1]:
        hi += 1
    middles = {(lo + hi) // 2, (lo + hi + 1) // 2}
    return min(middles, key=lambda k: (abs(angles[k]), k))


@dataclass(frozen=True)
class AntcarParams:
    """Antcar's route-centric lateralised mushroom body (Gattaux et al. 2025, Methods)."""

    n_kc: int = 15_000
    pn_per_kc: int = 4
    kappa: float = 0.01
    place_n_kc: int = 5_000
    amplitude_deg: float = 45.0
    step_deg: float = 5.0
    phase_deg: float = 0.0            # 180: learn looking back along the route (homing)
    place_amplitude_deg: float = 30.0
    k_v: float = 0.02                 # m per decision at full throttle
    sat_min: float = 0.25             # minimum throttle of sat(1 - lambda_max)
    k_phi: float = 8.0                # steering gain, rad per unit lambda_diff
    phi_max: float = 0.3              # steering limit (rad)
    turn_length: float = 0.02         # m: turn = step * tan(phi) / turn_length (Antcar's wheelbase, eq. 10)
    threshold: float = 0.2            # place-MBON lambda below which the place is recognised (p)
    task: str = "route"               # route | homing | shuttle
    seed: int = 0

    def __post_init__(self) -> None:
        if self.task not in ("route", "homing", "shuttle"):
            raise ValueError(f"Antcar task {self.task!r} not known; allowed: route, homing, shuttle")
        check_wiring(self.n_kc, self.pn_per_kc, self.kappa)
        check_wiring(self.place_n_kc, self.pn_per_kc, self.kappa, name="place_")
        _check_ranges("Antcar", self, {
            "amplitude_deg": (self.amplitude_deg > 0, "> 0 deg"), "step_deg": (self.step_deg > 0, "> 0 deg"),
            "place_amplitude_deg": (self.place_amplitude_deg > 0, "> 0 deg"), "k_v": (self.k_v > 0, "> 0 m"),
            "sat_min": (0 <= self.sat_min <= 1, "in [0, 1]"), "k_phi": (self.k_phi >= 0, ">= 0 rad"),
            "phi_max": (0 < self.phi_max < math.pi / 2, "in (0, pi/2) rad"),
            "turn_length": (self.turn_length > 0, "> 0 m"), "threshold": (0 <= self.threshold <= 1, "in [0, 1]")})


class AntcarModel:
    """Left/right route MBONs learned with in-silico oscillation; nest/feeder place MBONs; no scanning."""

    kind = "antcar"
    learns_continuously = True

    def __init__(self, n_pn: int, params: AntcarParams | None = None, mbons: dict[str, MBON] | None = None):
        self.params = p = params or AntcarParams()
        self.n_pn = n_pn
        self.route_kc = KenyonCells(n_pn, p.n_kc, p.pn_per_kc, p.kappa, p.seed)
        self.place_kc = KenyonCells(n_pn, p.place_n_kc, p.pn_per_kc, p.kappa, p.seed + 1)
        self.mbons = mbons or {
            "left": MBON(p.n_kc), "right": MBON(p.n_kc), "nest": MBON(p.place_n_kc), "feeder": MBON(p.place_n_kc)
        }
        self._theta = oscillation_angles(math.radians(p.amplitude_deg), math.radians(p.step_deg))
        self._place_theta = oscillation_angles(math.radians(p.place_amplitude_deg), math.radians(p.step_deg))
        self.motivation = 1
        self.learned_views = 0

    def reset(self) -> None:
        """Start a new run: motivation back to 1 (forward)."""
        self.motivation = 1

    def learn(self, view: View) -> None:
        """Equation 5: each oscillation sample goes to the right MBON if theta_e <= 0, to the left if >= 0."""
        centre = math.radians(self.params.phase_deg)
        active = self.route_kc.active(view.pns(centre + self._theta))
        self.mbons["right"].learn(active[self._theta <= 0])
        self.mbons["left"].learn(active[self._theta >= 0])
        self.learned_views += 1

    def learn_place(self, view: View, place: str) -> None:
        """Learn a route extremity ('nest' or 'feeder') with the place oscillation (A = 30 deg)."""
        if place not in ("nest", "feeder"):
            raise ValueError(f"place must be 'nest' or 'feeder', got {place!r}")
        centre = math.radians(self.params.phase_deg)
        self.mbons[place].learn(self.place_kc.active(view.pns(centre + self._place_theta)))

    def familiarities(self, pn: np.ndarray) -> dict[str, np.ndarray]:
        """lambda of every MBON for PN vectors (m, n_pn) (equation 7; 1 = novel)."""
        route = self.route_kc.active(pn)
        place = self.place_kc.active(pn)
        return {
            "left": self.mbons["left"].novelty(route),
            "right": self.mbons["right"].novelty(route),
            "nest": self.mbons["nest"].novelty(place),
            "feeder": self.mbons["feeder"].novelty(place),
        }

    def decide(self, view: View) -> Command:
        """Equations 8-9 and the motivation rules; the turn follows Antcar's kinematics (eq. 10)."""
        p = self.params
        lam = {k: float(v[0]) for k, v in self.familiarities(view.pns((0.0,))).items()}
        if p.task == "homing" and self.motivation == 1 and lam["nest"] < p.threshold:
            self.motivation = 0
        elif p.task == "shuttle":
            if self.motivation == 1 and lam["feeder"] < p.threshold:
                self.motivation = -1
            elif self.motivation == -1 and lam["nest"] < p.threshold:
                self.motivation = 1
        m = self.motivation
        diff = lam["left"] - lam["right"]
        lam_max = max(lam["left"], lam["right"])
        v = m * p.k_v * min(1.0, max(p.sat_min, 1.0 - lam_max))
        phi = float(np.clip(m * p.k_phi * diff, -p.phi_max, p.phi_max))
        turn = v * math.tan(phi) / p.turn_length
        trace = {
            "lambda_left": lam["left"], "lambda_right": lam["right"], "lambda_nest": lam["nest"],
            "lambda_feeder": lam["feeder"], "lambda_diff": diff, "lambda_max": lam_max, "motivation": float(m),
        }
        return Command(v, turn, trace)

    def lambda_diff(self, pn: np.ndarray) -> np.ndarray:
        """lambda_L - lambda_R for PN vectors (m, n_pn)."""
        active = self.route_kc.active(pn)
        return self.mbons["left"].novelty(active) - self.mbons["right"].novelty(active)


@dataclass(frozen=True)
class ArdinParams:
    """Ardin et al. 2016: one MBON, 20,000 KCs fed by 10 PNs each, ~1 % active; scan and step."""

    n_kc: int = 20_000
    pn_per_kc: int = 10
    kappa: float = 0.01
    scan_deg: float = 60.0
    scan_step_deg: float = 2.0
    step: float = 0.02                # m per decision
    seed: int = 0

    def __post_init__(self) -> None:
        check_wiring(self.n_kc, self.pn_per_kc, self.kappa)
        _check_scan("Ardin", self)


class ArdinModel:
    """A single familiarity MBON; route following by scanning and stepping toward the most familiar direction."""

    kind = "ardin"
    learns_continuously = False

    def __init__(self, n_pn: int, params: ArdinParams | None = None, mbons: dict[str, MBON] | None = None):
        self.params = p = params or ArdinParams()
        self.n_pn = n_pn
        self.kc = KenyonCells(n_pn, p.n_kc, p.pn_per_kc, p.kappa, p.seed)
        self.mbons = mbons or {"familiarity": MBON(p.n_kc)}
        self._scan = _scan_angles(math.radians(p.scan_deg), math.radians(p.scan_step_deg))
        self.learned_views = 0

    def reset(self) -> None:
        """Nothing to reset between runs."""

    def learn(self, view: View) -> None:
        self.mbons["familiarity"].learn(self.kc.active(view.pns((0.0,))))
        self.learned_views += 1

    def decide(self, view: View) -> Command:
        novelty = self.kc.novelty(view.pns(self._scan), [self.mbons["familiarity"]])[:, 0]
        i = _best_angle(self._scan, novelty)
        return Command(self.params.step, float(self._scan[i]), {"novelty": float(novelty[i])})


@dataclass(frozen=True)
class PerfectMemoryParams:
    """Perfect memory: every learned view stored; the visual compass picks the best-matching rotation."""

    scan_deg: float = 60.0
    scan_step_deg: float = 2.0
    step: float = 0.02

    def __post_init__(self) -> None:
        _check_scan("perfect memory", self)


class PerfectMemoryModel:
    """Stored views; rotational image difference (RMS over PNs) against all of them; the best match wins."""

    kind = "perfect_memory"
    learns_continuously = False

    def __init__(self, n_pn: int, params: PerfectMemoryParams | None = None, views: np.ndarray | None = None):
        self.params = p = params or PerfectMemoryParams()
        self.n_pn = n_pn
        views = np.zeros((0, n_pn), np.float32) if views is None else np.asarray(views, np.float32)
        if views.ndim != 2 or views.shape[1] != n_pn:
            raise ValueError(f"stored views must have shape (n, {n_pn}), got {views.shape}")
        self._scan = _scan_angles(math.radians(p.scan_deg), math.radians(p.scan_step_deg))
        # Preallocated (capacity, n_pn) store, doubled when full, and each view's squared norm, kept as learned.
        self._store = np.zeros((max(16, views.shape[0]), n_pn), np.float32)
        self._norms = np.zeros(self._store.shape[0], np.float32)
        self._n = 0
        for row in views:
            self._append(row[None, :])

    @property
    def views(self) -> np.ndarray:
        """The stored views (n, n_pn) float32 (a view of the store)."""
        return self._store[:self._n]

    @property
    def learned_views(self) -> int:
        return self._n

    def reset(self) -> None:
        """Nothing to reset between runs."""

    def _append(self, pn: np.ndarray) -> None:
        if self._n == self._store.shape[0]:
            self._store = np.concatenate([self._store, np.zeros_like(self._store)])
            self._norms = np.concatenate([self._norms, np.zeros_like(self._norms)])
        self._store[self._n] = pn[0]
        self._norms[self._n] = (pn * pn).sum(1)[0]
        self._n += 1

    def learn(self, view: View) -> None:
        self._append(view.pns((0.0,)))

    def differences(self, pn: np.ndarray) -> np.ndarray:
        """Smallest RMS difference (m,) between each PN vector (m, n_pn) and any stored view: one float32
        matrix product against the stored views, with their squared norms kept from learning."""
        if self._n == 0:
            raise RuntimeError("the perfect-memory model has learned no view yet")
        views = self.views
        sq = (pn * pn).sum(1)[:, None] + self._norms[None, :self._n] - 2.0 * pn @ views.T
        return np.sqrt(np.maximum(sq.min(axis=1), 0.0) / self.n_pn)

    def decide(self, view: View) -> Command:
        diff = self.differences(view.pns(self._scan))
        i = _best_angle(self._scan, diff)
        return Command(self.params.step, float(self._scan[i]), {"image_difference": float(diff[i])})


MODELS = {"antcar": (AntcarModel, AntcarParams), "ardin": (ArdinModel, ArdinParams),
          "perfect_memory": (PerfectMemoryModel, PerfectMemoryParams)}
MODELS.update(NAVIGATION_MODELS)


def make_model(kind: str, n_pn: int, **overrides):
    """A fresh model of `kind` (a key of MODELS) with parameters overridden by keyword."""
    try:
        cls, params_cls = MODELS[kind]
    except KeyError:
        raise ValueError(f"model {kind!r} not known; allowed: {', '.join(MODELS)}") from None
    known = {f.name for f in fields(params_cls)}
    unknown = set(overrides) - known
    if unknown:
        raise ValueError(f"unknown {kind} parameter(s) {sorted(unknown)}; allowed: {sorted(known)}")
    return cls(n_pn, params_cls(**overrides))


def parse_params(kind: str, texts: dict[str, str]) -> dict:
    """Parameter overrides of model `kind` given as text (`--param key=value`), each converted by the type of
    its parameter field: bool from true / false / 1 / 0, int from an integral number (2e4 = 20000), float from a
    finite number, str as given. One ValueError naming the parameter and what it allows for any other text."""
    try:
        params_cls = MODELS[kind][1]
    except KeyError:
        raise ValueError(f"model {kind!r} not known; allowed: {', '.join(MODELS)}") from None
    types = typing.get_type_hints(params_cls)
    out: dict = {}
    for key, text in texts.items():
        if key not in types:
            raise ValueError(f"unknown {kind} parameter {key!r}; allowed: {', '.join(sorted(types))}")
        name, kind_of = f"{kind} parameter {key}", types[key]
        if kind_of is bool:
            word = text.strip().lower()
            if word not in ("true", "false", "1", "0"):
                raise ValueError(f"{name} must be true or false (or 1 or 0), got {text!r}")
            out[key] = word in ("true", "1")
        elif kind_of in (int, float):
            try:
                value = int(text)
            except ValueError:
                try:
                    value = float(text)
                except ValueError:
                    value = text
            if kind_of is int and isinstance(value, float) and math.isfinite(value) and value.is_integer():
                value = int(value)
            out[key] = check_number(name, value, integer=kind_of is int)
        else:
            out[key] = text
    return out


def model_params(model) -> dict:
    return asdict(model.params)
