"""Route-following metrics as the field reports them.

- Gattaux et al. 2025: lateral error d (distance to the nearest point of the learned route) and angular error
  theta_e (heading minus the route's heading there), as median +- MAD; the memory metric PI_error (eq. 11-12);
  the stopping distance at the nest.
- Ardin et al. 2016: errors per route -- each time the agent is more than 20 cm from the route it counts one
  error and is put back on the route (done by the closed-loop runner; see `off_route`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from antarium.ant.routes import Route

ARDIN_ERROR_DISTANCE_M = 0.20


def json_text(record: Any) -> str:
    """`record` as strict JSON text (NaN, e.g. the metrics of a run that never reached the feeder, as null): what
    the files hold and the commands print."""
    def strict(v):
        if isinstance(v, dict):
            return {k: strict(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [strict(x) for x in v]
        if isinstance(v, float | np.floating):
            return float(v) if math.isfinite(v) else None
        return v

    return json.dumps(strict(record), indent=2, allow_nan=False, default=float)


def wrap(angle):
    """Angles wrapped to [-pi, pi)."""
    return np.remainder(np.asarray(angle, np.float64) + math.pi, math.tau) - math.pi


def median_mad(values) -> tuple[float, float]:
    """(median, median absolute deviation) of finite values; (nan, nan) when there are none."""
    v = np.asarray(values, np.float64)
    v = v[np.isfinite(v)]
    if v.size == 0:
        return math.nan, math.nan
    med = float(np.median(v))
    return med, float(np.median(np.abs(v - med)))


def route_errors(route: Route, xy, heading) -> tuple[np.ndarray, np.ndarray]:
    """Lateral error |d| (m) and angular error |theta_e| (rad) of positions (m, 2) and headings (m,) rad."""
    _, d, route_heading = route.project(xy)
    return np.abs(d), np.abs(wrap(np.asarray(heading, np.float64) - route_heading))


def off_route(route: Route, xy, limit: float = ARDIN_ERROR_DISTANCE_M) -> np.ndarray:
    """True where a position (m, 2) is farther than `limit` metres from the route (Ardin's error)."""
    _, d, _ = route.project(xy)
    return np.abs(d) > limit


def arrived(route: Route, xy, radius: float) -> bool:
    """Whether any position (m, 2) came within `radius` metres of the route's end."""
    xy = np.atleast_2d(np.asarray(xy, np.float64))
    return bool(np.any(np.hypot(*(xy - route.end).T) <= radius))


def stopping_distance(route: Route, xy_stop) -> float:
    """Distance (m) from where the ant stopped to the end of the route it followed (the nest when homing)."""
    return float(np.hypot(*(np.asarray(xy_stop, np.float64) - route.end)))


def pi_error(lambda_diff, theta_e) -> np.ndarray:
    """Antcar's PI_error (eq. 11-12): the cumulative mean of steering errors over test images.

    lambda_diff: (m,) lambda_L - lambda_R of each test image; theta_e: (m,) its heading error (rad, CCW > 0).
    With lambda = 1 for novel views (eq. 7), a view turned to the left of the route (theta_e > 0) is familiar to
    the left MBON, so the steering is right when lambda_diff < 0: e_i = 1 if sign(lambda_diff) != sign(-theta_e).
    Images with theta_e == 0 must be left out by the caller (the paper drops |theta_e| < 1 deg).
    Returns (m,) float64, PI_error(i) = mean(e_0..e_i).
    """
    lambda_diff = np.asarray(lambda_diff, np.float64)
    theta_e = np.asarray(theta_e, np.float64)
    if lambda_diff.shape != theta_e.shape:
        raise ValueError(f"lambda_diff {lambda_diff.shape} and theta_e {theta_e.shape} must have the same shape")
    e = (np.sign(lambda_diff) != np.sign(-theta_e)).astype(np.float64)
    return np.cumsum(e) / np.arange(1, e.size + 1)


def memory_pi_error(model, views, half_range_deg: float | None = None, step_deg: float = 1.0) -> float:
    """PI_error over learned views rotated by theta = +-`half_range_deg` (degrees) in `step_deg` steps (|theta| < 1
    deg left out) about the direction the model learned them in: the view's heading turned by the model's
    oscillation centre `phase_deg` (180: looking back along the route). The range defaults to the model's
    oscillation amplitude: the operating area its learning defines."""
    if half_range_deg is None:
        half_range_deg = model.params.amplitude_deg
    centre = math.radians(getattr(model.params, "phase_deg", 0.0))
    angles = np.radians(np.arange(-half_range_deg, half_range_deg + 1e-9, step_deg))
    angles = angles[np.abs(angles) >= math.radians(1.0) - 1e-12]
    diffs, thetas = [], []
    for view in views:
        diffs.append(model.lambda_diff(view.pns(centre + angles)))
        thetas.append(angles)
    if not diffs:
        raise ValueError("PI_error needs at least one view")
    return float(pi_error(np.concatenate(diffs), np.concatenate(thetas))[-1])


@dataclass(frozen=True)
class RunSummary:
    """The numbers of one closed-loop run on one route."""

    lateral_median: float
    lateral_mad: float
    angular_median_deg: float
    angular_mad_deg: float
    arrived: bool
    errors: int
    decisions: int
    distance: float
    stop_distance: float

    @classmethod
    def of(cls, route: Route, xy, heading, arrived_: bool, errors: int, stop_distance: float = math.nan):
        xy = np.atleast_2d(np.asarray(xy, np.float64))
        lat, ang = route_errors(route, xy, heading)
        lm, lmad = median_mad(lat)
        am, amad = median_mad(np.degrees(ang))
        dist = float(np.hypot(*np.diff(xy, axis=0).T).sum()) if len(xy) > 1 else 0.0
        return cls(lm, lmad, am, amad, bool(arrived_), int(errors), int(len(xy)), dist, float(stop_distance))


def motivation_switches(route: Route, xy, motivation) -> list[tuple[int, int, float, float]]:
    """Where a shuttling (or homing) ant changed its motivation M: (decision index, new M, distance to the nest,
    distance to the feeder) per change; xy (m, 2) positions, motivation (m,) the M of each decision.
    The nest is the route's start, the feeder its end (metres)."""
    xy = np.atleast_2d(np.asarray(xy, np.float64))
    m = np.asarray(motivation, np.float64)
    if m.shape != (xy.shape[0],):
        raise ValueError(f"motivation {m.shape} must have one value per position ({xy.shape[0]},)")
    changes = np.flatnonzero(np.diff(m) != 0) + 1
    return [(int(i), int(m[i]), float(np.hypot(*(xy[i] - route.start))), float(np.hypot(*(xy[i] - route.end))))
            for i in changes]
