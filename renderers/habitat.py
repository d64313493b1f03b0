"""The default scene: a seeded procedural ant habitat at ant scale (no download needed).

A 24 m x 24 m patch of ground (micro-relief of a few millimetres, so an eye at z = 0.01 m is about 1 cm
above it) with grass tussocks, stones, bushes and a few trees, under a clear sky with a sun, in front of a
distant panorama of hills and a tree-line. Colours are sRGB, shaded once by the sun (baked into vertex
colours), then mapped to G, B, UV by `channels`.
"""

from __future__ import annotations

import math

import numpy as np

from .channels import rgb_to_gbu, srgb_to_linear
from .panorama import Panorama
from .scene import MeshData, Scene, SceneObject
from .sky import Sky, sun_direction

SUN_AZIMUTH = math.radians(135.0)
SUN_ELEVATION = math.radians(40.0)
RELIEF_M = 0.003
#: Largest habitat side (m) and most objects of each kind (about 3 million triangles in all, built in under a minute:
#: 10,000 tussocks take 1.9 s); beyond them a scene load never ended (a billion tussocks) or failed on an object's
#: position instead of naming the parameter (a size of 1e9 m)
MAX_SIZE_M = 10_000.0
MAX_COUNTS = {"n_trees": 500, "n_bushes": 500, "n_tussocks": 50_000, "n_stones": 10_000}


def _shade(vertices: np.ndarray, faces: np.ndarray, srgb: np.ndarray, ambient: float = 0.45) -> np.ndarray:
    """Per-vertex linear G, B, UV radiance: sRGB albedo x (ambient + Lambert from the sun)."""
    tri = vertices[faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-12)
    sun = sun_direction(SUN_AZIMUTH, SUN_ELEVATION)
    light = ambient + (1 - ambient) * np.abs(vn @ sun)  # thin blades and leaves: two-sided
    return rgb_to_gbu(srgb_to_linear(srgb) * light[:, None])


def _mesh(vertices, faces, srgb, double_sided: bool = False) -> MeshData:
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    srgb = np.broadcast_to(np.asarray(srgb, dtype=np.float64), vertices.shape)
    return MeshData(vertices.astype(np.float32), faces.astype(np.uint32), _shade(vertices, faces, srgb),
                    double_sided=double_sided)


def _merge(parts):
    """Concatenate (vertices, faces, colours) parts into one."""
    vs, fs, cs, base = [], [], [], 0
    for v, f, c in parts:
        vs.append(v)
        fs.append(f + base)
        cs.append(np.broadcast_to(c, v.shape))
        base += len(v)
    return np.concatenate(vs), np.concatenate(fs), np.concatenate(cs)


def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    return np.asarray(s.vertices), np.asarray(s.faces)


def _ground(rng, size: float, cells: int):
    x = np.linspace(-size / 2, size / 2, cells + 1)
    gx, gy = np.meshgrid(x, x, indexing="ij")
    z = RELIEF_M * (np.sin(gx * 1.7 + rng.uniform(0, 6)) * np.cos(gy * 1.3 + rng.uniform(0, 6)))
    z += rng.uniform(-0.3, 0.3, z.shape) * RELIEF_M
    v = np.stack([gx.ravel(), gy.ravel(), z.ravel()], axis=1)
    i = np.arange(cells)[:, None] * (cells + 1) + np.arange(cells)[None, :]
    i = i.ravel()
    faces = np.concatenate([np.stack([i, i + cells + 1, i + 1], 1), np.stack([i + 1, i + cells + 1, i + cells + 2], 1)])
    # soil with patches of dry litter
    patch = 0.5 + 0.5 * np.sin(v[:, 0] * 0.9 + rng.uniform(0, 6)) * np.sin(v[:, 1] * 1.1 + rng.uniform(0, 6))
    soil = np.array([0.52, 0.44, 0.33]) * (1 - 0.3 * patch[:, None]) + np.array([0.60, 0.55, 0.38]) * 0.3 * patch[
        :, None]
    soil *= rng.uniform(0.85, 1.1, (len(v), 1))
    return _mesh(v, faces, np.clip(soil, 0, 1))


def _tussocks(rng, n: int, size: float, blades: int = 12):
    parts = []
    for _ in range(n):
        c = np.array([*rng.uniform(-size / 2, size / 2, 2), 0.0])
        h = rng.uniform(0.04, 0.18)
        ang = rng.uniform(0, 2 * np.pi, blades)
        lean = rng.uniform(0.1, 0.5, blades)
        hb = h * rng.uniform(0.6, 1.0, blades)
        w = 0.004
        base_l = c + np.stack([np.cos(ang + np.pi / 2) * w, np.sin(ang + np.pi / 2) * w, np.zeros(blades)], 1)
        base_r = c - np.stack([np.cos(ang + np.pi / 2) * w, np.sin(ang + np.pi / 2) * w, np.zeros(blades)], 1)
        mid = c + np.stack([np.cos(ang) * lean * hb * 0.4, np.sin(ang) * lean * hb * 0.4, hb * 0.55], 1)
        tip = c + np.stack([np.cos(ang) * lean * hb, np.sin(ang) * lean * hb, hb], 1)
        v = np.stack([base_l, base_r, mid, tip], 1).reshape(-1, 3)
        b = 4 * np.arange(blades)[:, None]
        f = np.concatenate([b + [0, 1, 2], b + [0, 2, 3]])
        col = np.array([0.55, 0.58, 0.30]) * rng.uniform(0.8, 1.15) + rng.uniform(-0.05, 0.05, 3)
        parts.append((v, f, np.clip(col, 0, 1)))
    return _mesh(*_merge(parts), double_sided=True)  # blades are seen from both sides


def _stones(rng, n: int, size: float):
    sv, sf = _icosphere(1)
    parts = []
    for _ in range(n):
        r = rng.uniform(0.01, 0.12)
        v = sv * r * rng.uniform(0.6, 1.4, 3) * (1 + rng.uniform(-0.15, 0.15, (len(sv), 1)))
        v[:, 2] = np.maximum(v[:, 2], -0.2 * r)  # sunk into the ground
        v += np.array([*rng.uniform(-size / 2, size / 2, 2), 0.0])
        col = np.array([0.58, 0.55, 0.52]) * rng.uniform(0.7, 1.1)
        parts.append((v, sf, col))
    return _mesh(*_merge(parts))


def _bush(rng):
    sv, sf = _icosphere(1)
    parts = []
    for _ in range(rng.integers(3, 6)):
        r = rng.uniform(0.25, 0.5)
        c = np.array([*rng.uniform(-0.35, 0.35, 2), r * rng.uniform(0.7, 1.1)])
        v = sv * r * (1 + rng.uniform(-0.12, 0.12, (len(sv), 1))) + c
        parts.append((v, sf, np.array([0.30, 0.40, 0.22]) * rng.uniform(0.8, 1.2)))
    return _mesh(*_merge(parts))


def _tree(rng):
    import trimesh

    height = rng.uniform(4.0, 8.0)
    trunk = trimesh.creation.cylinder(radius=rng.uniform(0.12, 0.25), height=height * 0.6, sections=16)
    tv = np.asarray(trunk.vertices) + [0, 0, height * 0.3]
    parts = [(tv, np.asarray(trunk.faces), np.array([0.45, 0.38, 0.32]))]
    sv, sf = _icosphere(2)
    for _ in range(rng.integers(4, 8)):
        r = rng.uniform(0.8, 1.6)
        c = np.array([*rng.uniform(-1.2, 1.2, 2), height * rng.uniform(0.6, 0.95)])
        v = sv * r * [1, 1, 0.7] * (1 + rng.uniform(-0.15, 0.15, (len(sv), 1))) + c
        parts.append((v, sf, np.array([0.42, 0.48, 0.36]) * rng.uniform(0.85, 1.15)))
    return _mesh(*_merge(parts))


def panorama_image(seed: int = 0, width: int = 2048) -> np.ndarray:
    """(H, W, 4) sRGB RGBA equirectangular image: distant hills and a tree-line, transparent sky."""
    rng = np.random.default_rng(seed + 1000)
    h = width // 2
    az = np.linspace(0, 2 * np.pi, width, endpoint=False)
    hills = np.zeros(width)
    for k in range(1, 9):
        hills += rng.uniform(0.2, 1.0) / k * np.sin(k * az + rng.uniform(0, 2 * np.pi))
    hills = np.radians(1.5 + 2.5 * (hills - hills.min()) / np.ptp(hills))
    trees = np.radians(rng.uniform(0.3, 1.8, width // 8).repeat(8)) * (rng.random(width // 8) < 0.7).repeat(8)
    trees = np.convolve(trees, np.ones(5) / 5, mode="same")
    el = (0.5 - (np.arange(h) + 0.5) / h) * np.pi
    img = np.zeros((h, width, 4))
    ground = el[:, None] <= hills[None, :]
    canopy = (el[:, None] <= hills[None, :] + trees[None, :]) & ~ground
    img[ground] = [0.45, 0.47, 0.42, 1.0]
    img[canopy] = [0.30, 0.36, 0.28, 1.0]
    img[el < 0] = [0.50, 0.45, 0.36, 1.0]
    return img


def habitat_objects(seed: int = 0, size: float = 24.0, n_trees: int = 5, n_bushes: int = 14,
                    n_tussocks: int = 900, n_stones: int = 160) -> dict[str, SceneObject]:
    """Named objects of the habitat: 'ground', 'tussocks', 'stones', 'bush_<i>', 'tree_<i>'."""
    if not (np.isfinite(size) and 20.0 <= size <= MAX_SIZE_M):
        raise ValueError(f"habitat size must be in [20, {MAX_SIZE_M:g}] m, got {size!r}")
    for name, n in (("n_trees", n_trees), ("n_bushes", n_bushes), ("n_tussocks", n_tussocks), ("n_stones", n_stones)):
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 0 <= n <= MAX_COUNTS[name]:
            raise ValueError(f"habitat {name} must be an integer in [0, {MAX_COUNTS[name]:,}], got {n!r}")
    rng = np.random.default_rng(seed)
    objects = {"ground": SceneObject(_ground(rng, size, 48))}
    if n_tussocks:
        objects["tussocks"] = SceneObject(_tussocks(rng, n_tussocks, size))
    if n_stones:
        objects["stones"] = SceneObject(_stones(rng, n_stones, size))
    for i in range(n_bushes):
        pos = (*rng.uniform(-size / 2 + 1, size / 2 - 1, 2), 0.0)
        objects[f"bush_{i}"] = SceneObject(_bush(rng), position=pos, yaw=rng.uniform(0, 2 * np.pi))
    for i in range(n_trees):
        pos = (*rng.uniform(-size / 2 + 2, size / 2 - 2, 2), 0.0)
        objects[f"tree_{i}"] = SceneObject(_tree(rng), position=pos, yaw=rng.uniform(0, 2 * np.pi))
    return objects


def habitat_scene(seed: int = 0, **kwargs) -> Scene:
    """The default habitat: objects, the distant panorama and the sky with its sun."""
    sky = Sky(sun_azimuth=SUN_AZIMUTH, sun_elevation=SUN_ELEVATION)
    pano = Panorama(panorama_image(seed))
    return Scene(far=[sky, pano], objects=habitat_objects(seed, **kwargs), name="habitat")
