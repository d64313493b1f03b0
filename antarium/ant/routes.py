"""Routes: polylines on the ground (metres, world frame), the route-centric (Frenet) frame, seeded curved routes."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from antarium.core.numbers import is_float_text


class RouteError(ValueError):
    """A route that cannot be followed: fewer than two distinct points, or non-finite coordinates."""


class Route:
    """A polyline of waypoints (n, 2) float64 metres, travelled from the first point (nest) to the last (feeder)."""

    def __init__(self, points) -> None:
        pts = np.asarray(points, dtype=np.float64)
        if pts.ndim != 2 or pts.shape[1] != 2:
            raise RouteError(f"a route must be an (n, 2) array of x, y in metres, got shape {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise RouteError("route coordinates must be finite numbers (metres)")
        pts = pts[np.concatenate([[True], np.any(pts[1:] != pts[:-1], axis=1)])]
        if pts.shape[0] < 2:
            raise RouteError(f"a route needs at least two distinct points, got {pts.shape[0]}")
        self.points = pts
        with np.errstate(over="ignore"):  # coordinates too far apart: refused below by their length
            seg = np.diff(pts, axis=0)
            self._seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self._seg = seg
        self._seg_heading = np.arctan2(seg[:, 1], seg[:, 0])
        self.cumulative = np.concatenate([[0.0], np.cumsum(self._seg_len)])
        if not math.isfinite(self.length):
            raise RouteError(f"a route's length must be a finite number of metres, got {self.length} from "
                             f"coordinates up to {np.abs(pts).max():.3g} m")

    @property
    def length(self) -> float:
        return float(self.cumulative[-1])

    @property
    def start(self) -> np.ndarray:
        return self.points[0]

    @property
    def end(self) -> np.ndarray:
        return self.points[-1]

    def at(self, s) -> tuple[np.ndarray, np.ndarray]:
        """Points (m, 2) and headings (m,) rad at arc lengths `s` (metres, clipped to the route)."""
        s = np.clip(np.atleast_1d(np.asarray(s, np.float64)), 0.0, self.length)
        i = np.clip(np.searchsorted(self.cumulative, s, side="right") - 1, 0, len(self._seg_len) - 1)
        t = (s - self.cumulative[i]) / self._seg_len[i]
        return self.points[i] + t[:, None] * self._seg[i], self._seg_heading[i]

    def sample(self, spacing: float) -> tuple[np.ndarray, np.ndarray]:
        """Points and headings every `spacing` metres from start to end (end included)."""
        if spacing <= 0:
            raise ValueError(f"route spacing must be > 0 m, got {spacing}")
        n = max(1, int(math.ceil(self.length / spacing)))
        return self.at(np.linspace(0.0, self.length, n + 1))

    def project(self, xy) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest route point of each position (m, 2): arc length s, signed lateral error d (left > 0), heading.

        Returns three (m,) float64 arrays (metres, metres, radians).
        """
        xy = np.atleast_2d(np.asarray(xy, np.float64))
        rel = xy[:, None, :] - self.points[None, :-1, :]
        t = np.clip((rel * self._seg[None]).sum(-1) / self._seg_len[None] ** 2, 0.0, 1.0)
        foot = self.points[None, :-1, :] + t[..., None] * self._seg[None]
        dist = np.hypot(*(xy[:, None, :] - foot).transpose(2, 0, 1))
        j = np.argmin(dist, axis=1)
        rows = np.arange(xy.shape[0])
        cross = self._seg[j, 0] * rel[rows, j, 1] - self._seg[j, 1] * rel[rows, j, 0]
        d = np.copysign(dist[rows, j], cross)
        s = self.cumulative[j] + t[rows, j] * self._seg_len[j]
        return s, d, self._seg_heading[j]

    def reversed(self) -> Route:
        return Route(self.points[::-1])

    def save(self, path: str | os.PathLike) -> None:
        """Write the waypoints as CSV (x_m, y_m)."""
        np.savetxt(path, self.points, delimiter=",", header="x_m,y_m", comments="")

    @classmethod
    def load(cls, path: str | os.PathLike) -> Route:
        """Read a route file: CSV or whitespace x_m, y_m[, heading_deg] (metres; a header row naming the columns,
        blank lines and # comments allowed), the one reader of `antarium ant experiment`'s route sets
        (`read_route_file`); a heading_deg column is not part of the route. RouteError naming the
        file and line of anything else."""
        return read_route_file(Path(path))[0]


#: the columns a route file's header may name (case aside): x_m and y_m required, heading_deg optional
ROUTE_COLUMNS = ("x_m", "y_m", "heading_deg")


def _header(path: Path, names: list[str]) -> list[int]:
    """Column indices of x_m, y_m and heading_deg (-1: none) named by a header row (`ROUTE_COLUMNS`)."""
    names = [n.strip().strip("\"'").lower() for n in names]
    other = [n for n in names if n not in ROUTE_COLUMNS]
    twice = [n for n in ROUTE_COLUMNS if names.count(n) > 1]
    if other or twice or "x_m" not in names or "y_m" not in names:
        raise RouteError(f"{path}: header {', '.join(names)!r} — a route file's header names the columns x_m, y_m "
                         "(metres) and optionally heading_deg (degrees), each once, and no others")
    return [names.index(n) if n in names else -1 for n in ROUTE_COLUMNS]


def read_route_csv(path: Path) -> tuple[np.ndarray, float | None]:
    """(P, 2) float64 x, y (m) and the release heading (rad, or None) of a CSV / whitespace route file.

    A header is a first row with a field that is not a number (float() refuses it); it names its columns
    (`ROUTE_COLUMNS`). Without one the columns are x_m, y_m[, heading_deg] in that order. Every value is a
    finite number, but a heading_deg cell after the first row may be empty (a spreadsheet's export of a heading
    given once: only the first row's is used). Raises RouteError naming the file and line."""
    lines = [(n, ln) for n, ln in enumerate(path.read_text(encoding="utf-8-sig").splitlines(), 1)
             if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise RouteError(f"{path}: empty route file; expected columns x_m, y_m (and optionally heading_deg)")
    delimiter = "," if any("," in ln for _, ln in lines) else None
    first = [f.strip() for f in lines[0][1].split(delimiter)]
    has_header = not all(is_float_text(f) for f in first)
    if has_header:
        x, y, h = _header(path, first)
    heading_column = h if has_header else 2  # without a header, a third column
    rows = []
    for n, line in lines[int(has_header):]:
        row = []
        for k, field in enumerate(f.strip() for f in line.split(delimiter)):
            if not field and rows and k == heading_column:
                row.append(math.nan)  # never read: the release heading is the first row's
                continue
            if not is_float_text(field) or not math.isfinite(float(field)):
                raise RouteError(f"{path}, line {n}: {field!r} is not a {'finite ' * is_float_text(field)}number; a "
                                 "route file holds x_m, y_m[, heading_deg] numbers (metres, degrees), finite, with an "
                                 "optional header row")
            row.append(float(field))
        rows.append(row)
        width = len(first) if has_header else len(rows[0])
        if len(row) != width:
            raise RouteError(f"{path}, line {n}: {len(row)} columns where the "
                             f"{'header names' if has_header else 'rows before have'} {width}")
    if not rows:
        raise RouteError(f"{path}: a header and no points; expected rows of x_m, y_m (and optionally heading_deg)")
    if not has_header:
        if not 2 <= len(rows[0]) <= 3:
            raise RouteError(f"{path}: a route file needs columns x_m, y_m (metres), got {len(rows[0])} column(s) "
                             "(without a header: x_m, y_m and optionally heading_deg, in that order)")
        x, y, h = 0, 1, 2 if len(rows[0]) == 3 else -1
    data = np.array(rows, np.float64)
    return data[:, [x, y]], math.radians(float(data[0, h])) if h >= 0 else None


def read_route_file(path: Path) -> tuple[Route, float | None]:
    """The route of a CSV / whitespace route file (`read_route_csv`) and its release heading (rad, or None).
    Raises RouteError naming the file."""
    xy, heading = read_route_csv(path)
    try:
        return Route(xy), heading
    except RouteError as exc:
        raise RouteError(f"{path}: {exc}") from None


def curved_route(seed: int, length: float = 10.0, start=(0.0, 0.0), heading: float | None = None,
                 spacing: float = 0.05, curvature: float = 0.3, correlation: float = 2.0) -> Route:
    """A smooth random route of `length` metres from `start`.

    The curvature (1/m) is an Ornstein-Uhlenbeck process in arc length with standard deviation `curvature` and
    correlation length `correlation` (m); the first heading is uniform unless given. Same seed, same route.
    """
    if not all(math.isfinite(v) and v > 0 for v in (length, spacing)):
        raise ValueError(f"route length and spacing must be finite numbers > 0 m, got {length}, {spacing}")
    rng = np.random.default_rng(seed)
    n = max(2, int(round(length / spacing)))
    h = rng.uniform(-math.pi, math.pi) if heading is None else float(heading)
    a = math.exp(-spacing / correlation)
    k = 0.0
    pts = [np.asarray(start, np.float64)]
    for _ in range(n):
        k = a * k + math.sqrt(1 - a * a) * curvature * rng.standard_normal()
        h += k * spacing
        pts.append(pts[-1] + spacing * np.array([math.cos(h), math.sin(h)]))
    return Route(np.array(pts))
