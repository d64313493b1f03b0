"""A cluttered arena for the virtual ant (Mitchell 2019's seed task): striped cylinders under the sky, placed at
random outside a clear zone around the nest; the sky stays the compass.

`clutter_scene(seed)` is the renderer's `Scene`; `Clutter.collisions(xy)` counts the decisions at which the ant
(a disc of `ANT_RADIUS_M`) overlapped a cylinder.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: the ant's body, as a disc (m)
ANT_RADIUS_M = 0.005


@dataclass(frozen=True)
class Clutter:
    """Cylinders: centres (n, 2) m, radii (n,) m, height (m)."""

    centres: np.ndarray
    radii: np.ndarray
    height: float = 0.1

    def clearance(self, xy) -> np.ndarray:
        """(P,) distance (m) from each position (P, 2) to the nearest cylinder's surface."""
        xy = np.asarray(xy, np.float64).reshape(-1, 2)
        d = np.linalg.norm(xy[:, None, :] - self.centres[None], axis=2) - self.radii[None]
        return d.min(axis=1)

    def collisions(self, xy) -> int:
        """Decisions at which the ant overlapped a cylinder."""
        return int((self.clearance(xy) < ANT_RADIUS_M).sum())


def make_clutter(seed: int, n: int = 60, arena_radius: float = 3.0, clear_radius: float = 0.3,
                 radius_range=(0.02, 0.05), height: float = 0.1, min_gap: float = 0.15) -> Clutter:
    """`n` cylinders in a disc of `arena_radius` m, none within `clear_radius` of the nest (origin), gaps >=
    `min_gap` m between them (rejection sampling)."""
    rng = np.random.default_rng(seed)
    centres, radii = [], []
    tries = 0
    while len(centres) < n and tries < 100 * n:
        tries += 1
        r = arena_radius * math.sqrt(rng.uniform())
        a = rng.uniform(0, math.tau)
        c = np.array([r * math.cos(a), r * math.sin(a)])
        rad = rng.uniform(*radius_range)
        if r - rad < clear_radius:
            continue
        if any(np.hypot(*(c - o)) - rad - ro < min_gap for o, ro in zip(centres, radii, strict=True)):
            continue
        centres.append(c)
        radii.append(rad)
    return Clutter(np.asarray(centres), np.asarray(radii), height)


def _cylinder(radius: float, height: float, segments: int = 16, stripes: int = 4):
    """(vertices, faces, colours) of an open cylinder with `stripes` dark/light vertical stripe pairs."""
    a = np.repeat(np.arange(segments) * (math.tau / segments), 2)
    a = np.concatenate([a[1:], [math.tau]])  # each segment its own pair of edges (flat stripes)
    ring = np.stack([radius * np.cos(a), radius * np.sin(a)], axis=1)
    v = np.concatenate([np.c_[ring, np.zeros(len(ring))], np.c_[ring, np.full(len(ring), height)]])
    m = len(ring)
    faces = []
    for k in range(0, m - 1, 2):
        faces += [(k, k + 1, m + k + 1), (k, m + k + 1, m + k)]
    segment = np.arange(m) // 2
    shade = np.where((segment * 2 * stripes // segments) % 2 == 0, 0.05, 0.35)
    colours = np.tile(np.repeat(shade[:, None], 3, axis=1), (2, 1))
    return v.astype(np.float32), np.asarray(faces, np.uint32), colours.astype(np.float32)


def clutter_scene(clutter: Clutter, sky: dict | None = None):
    """The renderer's `Scene`: the default sky (or `sky`, parameters of the "sky" scene) and the cylinders."""
    from antarium.renderers import build_scene
    from antarium.renderers.scene import MeshData, Scene, SceneObject

    base = build_scene({"scene": "sky", **(sky or {})})
    objects = {}
    for i, (c, r) in enumerate(zip(clutter.centres, clutter.radii, strict=True)):
        v, f, col = _cylinder(float(r), clutter.height)
        objects[f"cylinder_{i}"] = SceneObject(MeshData(v, f, col, double_sided=True), (float(c[0]), float(c[1]), 0.0))
    return Scene(far=list(base.far), objects=objects, name="clutter")
