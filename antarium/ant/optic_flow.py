"""Optic-flow collision avoidance (OFCA) on the dome's own pixel lattice (Mitchell 2019 section 2.2).

Dense flow: for every green/blue pixel in a band about the horizon (|elevation| <= `max_elevation_deg`), the
brightness change between two consecutive LED frames and the spatial gradient on the sphere's tangent plane
(east, north; least squares over its `neighbours` nearest pixels, precomputed) give a Lucas-Kanade flow (rad per
frame) over the same neighbourhood. Free-yaw: the dome does not turn when the ant turns on its pin, so the flow
between frames is the translation's alone; the pixels' azimuths are taken relative to the ant's body.

Two ways to turn (both return a turn in rad, > 0 = left, and their trace):
- "filter" (the earlier filtering method): the expected flow of a forward translation (unit nearness,
  -(f - (f.d) d) for forward f) is matched with the observed flow; the nearness per pixel is the projection on
  it (1/m once divided by the distance walked; only pixels nearer than `react_distance` count); the ant turns
  away from the side (left: body azimuth 0..90 deg, right: -90..0) with more nearness,
  turn = -gain * (L - R) / (L + R + half_nearness).
- "foe" (the seed's focus-of-expansion method): least squares over the frontal field as eq. 1 is printed (A = [u v],
  b = x v - y u, in body azimuth / elevation coordinates); with that A it solves for (-y0, x0) of the FOE
  (x0, y0), and its first component, minus the FOE's elevation (near 0 for a level forward walk), is the centre
  (trace "foe_azimuth"): the flow magnitude (relative to a unit-nearness translation's) left and right of it is
  summed, and the ant turns away from the side with more, by the same formula. Split at the true FOE azimuth
  (A = [v -u]) the turn loses its side: the fit is pulled ~0.2-0.36 rad towards a near cylinder, which then
  counts partly on the other side (measured 2026-11-27).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from antarium.ant.command import clip_turn
from antarium.ant.tables import index_table

METHODS = ("filter", "foe")


@dataclass(frozen=True)
class FlowParams:
    max_elevation_deg: float = 30.0
    neighbours: int = 8
    method: str = "filter"
    gain: float = 0.5                 # rad of turn at full imbalance
    max_turn: float = 0.4             # rad per decision
    react_distance: float = 0.2       # m: pixels whose flow puts them nearer than this count
    half_nearness: float = 500.0      # summed nearness (1/m, both sides) at which the turn reaches half its gain
    frontal_deg: float = 90.0         # the sides span body azimuth 0..frontal (left) and -frontal..0 (right)

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"optic-flow method {self.method!r} not known; allowed: {', '.join(METHODS)}")
        if self.neighbours < 3 or not 0 < self.max_elevation_deg <= 90:
            raise ValueError("optic flow needs neighbours >= 3 and max_elevation_deg in (0, 90]")


class OpticFlow:
    """Dense optic flow on the dome's green/blue pixels. directions (N, 3); is_uv (N,) bool; gain (N,)."""

    def __init__(self, directions, is_uv, gain=None, params: FlowParams | None = None):
        self.params = p = params or FlowParams()
        directions = np.asarray(directions, np.float64)
        self.n_leds = directions.shape[0]
        d_all = directions / np.linalg.norm(directions, axis=1, keepdims=True)
        gb = np.flatnonzero(~np.asarray(is_uv, bool))
        band = gb[np.abs(d_all[gb, 2]) <= math.sin(math.radians(p.max_elevation_deg))]
        self.pixels = band
        d = d_all[band]
        self.directions = d
        self.azimuth = np.arctan2(d[:, 1], d[:, 0])
        self.elevation = np.arcsin(np.clip(d[:, 2], -1, 1))
        east = np.stack([-np.sin(self.azimuth), np.cos(self.azimuth), np.zeros(len(d))], axis=1)
        north = np.cross(d, east)
        self.east, self.north = east, north
        _, nb = cKDTree(d).query(d, k=p.neighbours + 1)
        self._nb = index_table(nb[:, 1:], len(d))
        # the kernels read only the horizontal components (M, 2), kept compact (the tables a decision reads)
        self._east_xy, self._north_xy = np.ascontiguousarray(east[:, :2]), np.ascontiguousarray(north[:, :2])
        off = d[self._nb] - d[:, None, :]                                   # (M, k, 3)
        a = np.stack([np.einsum("mkj,mj->mk", off, east), np.einsum("mkj,mj->mk", off, north)], axis=2)
        self._pinv = np.linalg.pinv(a)                                      # (M, 2, k): gradient from differences
        gain = np.ones(self.n_leds) if gain is None else np.asarray(gain, np.float64)
        self._scale = 1.0 / (65535.0 * gain[band])

    @classmethod
    def from_dome(cls, dome, params: FlowParams | None = None) -> OpticFlow:
        return cls(dome.directions, dome.is_uv, dome.gain, params)

    def intensity(self, leds: np.ndarray) -> np.ndarray:
        """(M,) intensity of the band's pixels (green + blue over the full scale and the gain) in an (N, 2) frame."""
        from antarium.ant.flow_kernels import band_intensity

        leds = np.asarray(leds)
        if leds.shape != (self.n_leds, 2):
            raise ValueError(f"LED values must have shape ({self.n_leds}, 2), got {leds.shape}")
        return band_intensity(leds, self.pixels, self._scale)

    def flow(self, before: np.ndarray, after: np.ndarray, need: np.ndarray | None = None) -> np.ndarray:
        """(M, 2) flow (east, north; rad per frame) of the band's pixels between two (N, 2) LED frames: Lucas-Kanade
        over each pixel and its neighbours (compiled, `flow_kernels`); with `need` (M,) bool, only those pixels'
        (zero elsewhere)."""
        return self.flow_of(self.intensity(before), self.intensity(after), need)

    def flow_of(self, i0: np.ndarray, i1: np.ndarray, need: np.ndarray | None = None) -> np.ndarray:
        """`flow` from the two frames' band intensities (M,) (`intensity`)."""
        from antarium.ant.flow_kernels import lucas_kanade

        need = np.ones(self.pixels.size, bool) if need is None else np.asarray(need, bool)
        return lucas_kanade(i0, i1, self._nb, self._pinv, need)

    def avoid(self, before: np.ndarray, after: np.ndarray, yaw: float, travelled: float) -> tuple[float, dict]:
        """The turn (rad, > 0 left) away from the nearer side for an ant facing dome azimuth `yaw` that walked
        `travelled` m between the frames, and a trace. A pixel's nearness (1/m) is its flow over the flow of a
        unit-distance translation, divided by the distance walked."""
        return self.avoid_of(self.intensity(before), self.intensity(after), yaw, travelled)

    def avoid_of(self, i0: np.ndarray, i1: np.ndarray, yaw: float, travelled: float) -> tuple[float, dict]:
        """`avoid` from the two frames' band intensities (M,) (`intensity`)."""
        from antarium.ant.flow_kernels import filter_turn_sides, frontal_field

        p = self.params
        trace: dict[str, float] = {}
        if p.method == "filter":  # the flow of the frontal pixels that count, in one compiled pass
            left, right = filter_turn_sides(i0, i1, self._nb, self._pinv, self.azimuth, self._east_xy, self._north_xy,
                                            float(yaw), math.radians(p.frontal_deg), float(travelled),
                                            p.react_distance)
        else:
            rel, expected, norm2, ok = frontal_field(self.azimuth, self._east_xy, self._north_xy, float(yaw),
                                                     math.radians(p.frontal_deg))
            flow = self.flow_of(i0, i1, ok)        # only the frontal pixels that count
            x, y = rel[ok], self.elevation[ok]
            u, v = flow[ok, 0], flow[ok, 1]  # east: azimuth grows to the left
            # eq. 1 as printed (A = [u v]): each flow line through the FOE (x0, y0) gives x0 v - y0 u = x v - y u, so
            # this solves for (-y0, x0) and foe[0] is minus the FOE's elevation (see the module docstring)
            foe, *_ = np.linalg.lstsq(np.stack([u, v], axis=1), x * v - y * u, rcond=None)
            centre = float(np.clip(foe[0], -math.radians(p.frontal_deg), math.radians(p.frontal_deg)))
            trace["foe_azimuth"] = centre
            nearness = np.sqrt((flow ** 2).sum(1) / np.maximum(norm2, 1e-12)) / max(travelled, 1e-6)
            nearness = np.where(nearness > 1.0 / p.react_distance, nearness, 0.0)
            left = float(nearness[ok & (rel > centre)].sum())
            right = float(nearness[ok & (rel < centre)].sum())
        trace.update(flow_left=left, flow_right=right)
        turn = -p.gain * (left - right) / (left + right + p.half_nearness)
        turn = clip_turn(turn, p.max_turn)
        return turn, {**trace, "flow_turn": turn}


class CollisionAvoidance:
    """OFCA over consecutive decisions: `turn(leds, yaw)` compares with the frame of the previous call; `forget()`
    after the ant was carried (the next call then sees no flow)."""

    def __init__(self, flow: OpticFlow) -> None:
        self.flow = flow
        self._last: np.ndarray | None = None

    def forget(self) -> None:
        self._last = None

    def turn(self, leds: np.ndarray, yaw: float, travelled: float) -> tuple[float, dict[str, float]]:
        now = self.flow.intensity(leds)            # each frame's band read once (a new array: no copy of the frame)
        last, self._last = self._last, now
        if last is None or travelled <= 0:
            return 0.0, {"flow_turn": 0.0}
        return self.flow.avoid_of(last, now, yaw, travelled)
