"""Routes: polylines on the ground (metres, world frame), the route-centric (Frenet) frame, seeded curved routes."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np


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
        keep = np.concatenate([[True], np.any(np.diff(pts, axis=0) != 0, axis=1)])
        pts = pts[keep]
        if pts.shape[0] < 2:
            raise RouteError(f"a route needs at least two distinct points, got {pts.shape[0]}")
        self.points = pts
        seg = np.diff(pts, axis=0)
        self._seg = seg
        self._seg_len = np.hypot(seg[:, 0], seg[:, 1])
        self._seg_heading = np.arctan2(seg[:, 1], seg[:, 0])
        self.cumulative = np.concatenate([[0.0], np.cumsum(self._seg_len)])

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
        """Read a CSV or whitespace path file with columns x, y in metres (a header line is allowed)."""
        path = Path(path)
        text = path.read_text()
        delimiter = "," if "," in text else None
        first = text.lstrip().split("\n", 1)[0]
        has_header = any(c.isalpha() and c not in "eE" for c in first)
        try:
            pts = np.loadtxt(path, delimiter=delimiter, skiprows=int(has_header), ndmin=2)
        except ValueError as exc:
            raise RouteError(f"{path}: not a path file of x, y metres ({exc})") from None
        if pts.shape[1] < 2:
            raise RouteError(f"{path}: a path file needs two columns (x_m, y_m), got {pts.shape[1]}")
        return cls(pts[:, :2])


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
