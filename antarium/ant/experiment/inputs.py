"""Real inputs of an experiment: worlds (a named scene, any mesh or panorama, at a stated scale, up axis and eye
height) and route sets (a folder or glob of route files), each route checked against the world it is run in.

Route files: CSV (or whitespace) with `x_m, y_m` and an optional `heading_deg` column (a header row allowed: it
names these columns and no others, `routes.ROUTE_COLUMNS`; without one they come in that order), or a trial log (.h5:
the pose's x, y of every frame). `heading_deg` of the first row is the heading the ant is released with (degrees
CCW from +x); otherwise the route's own.

The ground is a surface facing up (`ground_along`); a run renders its world lowered by its lowest point
(`run_world`), so that worlds in survey coordinates run, reported in their own coordinates.
"""

from __future__ import annotations

import glob
import hashlib
import itertools
import math
import os
from dataclasses import dataclass, replace
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from antarium.ant.routes import Route, RouteError, read_route_file

ROUTE_SUFFIXES = (".csv", ".txt", ".tsv", ".h5", ".hdf5")
UP_AXES = ("z", "y")
#: a triangle is ground (something the eye cannot be under) when its normal is this close to vertical
GROUND_NORMAL_Z = 0.5
#: surfaces over a point closer in height than this (m) are one (the triangles sharing an edge or a corner there)
SAME_SURFACE_M = 1e-6
#: route points are checked against the ground every this many metres
CHECK_SPACING_M = 0.05
#: the ground at a route's start has at least this much free space above it (m; or twice the eye height)
GROUND_CLEARANCE_M = 0.05


class WorldError(ValueError):
    """A world that cannot be loaded as stated (scale, up axis, eye height, file)."""


@dataclass(frozen=True)
class WorldSpec:
    """A world as an experiment names it: a scene name or file, its scale (world metres per file unit), which
    file axis is up (GLB/GLTF are +y up by their standard and converted on loading: give "y" or leave the
    default), and the eye's height above the ground under the route's start (m). `digest`: the SHA-1 of the
    scene file and the files it names (`scene_digest`) when the spec was read ("" for a named scene), so that an
    edited file is another world (another run id, not a stale cached one)."""

    scene: str
    name: str = ""
    scale: float = 1.0
    up: str = "z"
    eye_height_m: float = 0.01
    params: tuple = ()          # extra scene parameters (key, value) pairs, e.g. (("seed", 3),) for the habitat
    digest: str = ""

    def __post_init__(self) -> None:
        if self.up not in UP_AXES:
            raise WorldError(f"world {self.scene!r}: up must be one of {', '.join(UP_AXES)}, got {self.up!r}")
        if not (math.isfinite(self.scale) and self.scale > 0):
            raise WorldError(f"world {self.scene!r}: scale must be a positive number (m per unit), got {self.scale!r}")
        if not (math.isfinite(self.eye_height_m) and self.eye_height_m > 0):
            raise WorldError(f"world {self.scene!r}: eye_height_m must be > 0 m, got {self.eye_height_m!r}")
        if not self.name:
            object.__setattr__(self, "name", Path(self.scene).stem)


def file_digest(path: str | Path) -> str:
    """SHA-1 (hex) of a file's bytes."""
    h = hashlib.sha1()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


#: words that open an MTL line naming a texture file (its last word)
MTL_TEXTURES = ("map_", "bump", "disp", "decal", "refl", "norm")


def scene_files(path: str | Path) -> list[Path]:
    """A scene file and the files it names that its loader reads, those that exist: a glTF's or GLB's external
    buffers and images (`uri`s, not data: URIs), an OBJ's MTL files (`mtllib`) and their textures (map_Kd and
    the other map_*, bump, disp, decal, refl, norm lines: the last word), all next to it."""
    path = Path(path)
    folder, names = path.parent, []
    suffix = path.suffix.lower()
    if suffix in (".gltf", ".glb"):
        from antarium.renderers.meshes import gltf_json

        try:
            doc = gltf_json(path)
        except ValueError:  # unreadable: the loader will say so; no files named
            doc = {}
        names = [unquote(item["uri"]) for key in ("buffers", "images") for item in doc.get(key, [])
                 if isinstance(item, dict) and isinstance(item.get("uri"), str) and not item["uri"].startswith("data:")]
    elif suffix == ".obj":
        for line in path.read_bytes().decode("utf-8", "replace").splitlines():
            words = line.split()
            if len(words) >= 2 and words[0] == "mtllib":
                mtls = [" ".join(words[1:]), *words[1:]]
                names += mtls
                for mtl in (folder / m for m in mtls):
                    if mtl.is_file():
                        names += [w[-1] for w in (ln.split() for ln in mtl.read_bytes().decode("utf-8", "replace")
                                                  .splitlines()) if len(w) >= 2 and w[0].startswith(MTL_TEXTURES)]
    found = sorted({folder / n for n in names if (folder / n).is_file() and (folder / n) != path})
    return [path, *found]


def scene_digest(path: str | Path) -> str:
    """SHA-1 (hex) of a scene file and every file it names (`scene_files`): an edited buffer, material or texture
    is another world."""
    h = hashlib.sha1()
    for f in scene_files(path):
        h.update(f"{f.relative_to(Path(path).parent).as_posix()}\0{file_digest(f)}\n".encode())
    return h.hexdigest()


def route_digest(route: Route) -> str:
    """SHA-1 (hex) of a route's points (float64 x, y in metres): what a run learns and is released on."""
    return hashlib.sha1(np.ascontiguousarray(route.points, np.float64).tobytes()).hexdigest()


def _is_gltf(scene: str) -> bool:
    return Path(scene).suffix.lower() in (".glb", ".gltf")


def build_world(world: WorldSpec):
    """The `Scene` of `world`: its meshes scaled to metres and turned +z up. Raises WorldError / FileNotFoundError."""
    from antarium.renderers import build_scene
    from antarium.renderers.meshes import UP_AXES as TURN_UP
    from antarium.renderers.scene import MeshData, SceneObject

    if _is_gltf(world.scene) and world.up != "y":
        raise WorldError(f"world {world.scene}: GLB/GLTF files are +y up by their standard; give up = \"y\"")
    if world.digest and Path(world.scene).is_file() and scene_digest(world.scene) != world.digest:
        raise WorldError(f"world {world.scene!r}: the file changed since the spec was read; read the spec again")
    try:
        scene = build_scene({"scene": world.scene, **dict(world.params)})
    except (ValueError, FileNotFoundError) as exc:
        raise WorldError(f"world {world.scene!r}: {exc}") from None
    turn = world.up == "y" and not _is_gltf(world.scene)
    if world.scale == 1.0 and not turn:
        return scene
    rot = TURN_UP["y" if turn else "z"][:3, :3]  # the mesh loader's turn to +z up; then the scale
    for name, obj in list(scene.objects.items()):
        m = obj.mesh
        v = (np.asarray(m.vertices, np.float64) @ rot.T * world.scale).astype(np.float32)
        mesh = MeshData(v, m.faces, m.colours, m.uv, m.texture, m.double_sided)
        pos = rot @ np.asarray(obj.position, np.float64) * world.scale
        scene.objects[name] = SceneObject(mesh, tuple(pos), obj.yaw, obj.scale)
    return scene


_WORLDS: dict = {}


def cached_world(world: WorldSpec):
    """`build_world`, once per process (a Dask worker builds each world once and reuses it across runs)."""
    if world not in _WORLDS:
        _WORLDS[world] = build_world(world)
    return _WORLDS[world]


_RUN_WORLDS: dict = {}


def run_world(world: WorldSpec):
    """(the `Scene` a run renders, its z = 0 in the world's own z (m)): `cached_world` lowered by its lowest point
    (0 for a panorama world), once per process. The frame loop takes an eye 0..1000 m above z = 0, so a world in
    survey coordinates (its ground below z = 0, or far above it) runs lowered; x and y, and so the tracks, are the
    world's own. The meshes are shared with `cached_world`'s scene, only their positions move."""
    from antarium.renderers.scene import SceneObject

    if world not in _RUN_WORLDS:
        scene = cached_world(world)
        tris = _triangles(scene)
        floor = float(tris[..., 2].min()) if len(tris) else 0.0
        if floor != 0.0:
            scene = replace(scene, objects={
                name: SceneObject(o.mesh, (o.position[0], o.position[1], o.position[2] - floor), o.yaw, o.scale)
                for name, o in scene.objects.items()})
        _RUN_WORLDS[world] = scene, floor
    return _RUN_WORLDS[world]


def _triangles(scene) -> np.ndarray:
    """(T, 3, 3) float64 world-frame triangles of every object of `scene` (empty for a panorama world)."""
    tris = [obj.world_vertices()[np.asarray(obj.mesh.faces, np.int64)] for obj in scene.objects.values()]
    return np.concatenate(tris).astype(np.float64) if tris else np.zeros((0, 3, 3))


def ground_candidates(triangles: np.ndarray, xy: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Every near-horizontal triangle (|normal z| >= GROUND_NORMAL_Z) over each point: its height and whether it
    faces up (its corners counter-clockwise seen from above, as the top of a slab or a terrain is wound).

    triangles: (T, 3, 3) float64 m; xy: (P, 2) float64 m. Returns P pairs (heights (K,) float64 m ascending,
    faces up (K,) bool), one per surface (triangles within SAME_SURFACE_M of each other there are one, facing up if
    any does); K = 0 where nothing is over the point.
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    n = np.cross(b - a, c - a)
    norm = np.linalg.norm(n, axis=1)
    flat = (norm > 0) & (np.abs(n[:, 2]) >= GROUND_NORMAL_Z * np.where(norm > 0, norm, 1.0))
    a, b, c, up = a[flat], b[flat], c[flat], n[flat, 2] > 0
    lo = np.minimum(np.minimum(a, b), c)[:, :2]
    hi = np.maximum(np.maximum(a, b), c)[:, :2]
    out = []
    for p in np.asarray(xy, np.float64):
        k = np.flatnonzero(np.all((lo <= p) & (p <= hi), axis=1))
        # barycentric coordinates of p in each candidate triangle's xy projection
        v0, v1, v2 = b[k, :2] - a[k, :2], c[k, :2] - a[k, :2], p - a[k, :2]
        den = v0[:, 0] * v1[:, 1] - v1[:, 0] * v0[:, 1]
        ok = np.abs(den) > 1e-15
        den = np.where(ok, den, 1.0)
        u = (v2[:, 0] * v1[:, 1] - v1[:, 0] * v2[:, 1]) / den
        w = (v0[:, 0] * v2[:, 1] - v2[:, 0] * v0[:, 1]) / den
        inside = ok & (u >= -1e-9) & (w >= -1e-9) & (u + w <= 1 + 1e-9)
        z = (a[k, 2] + u * (b[k, 2] - a[k, 2]) + w * (c[k, 2] - a[k, 2]))[inside]
        order = np.argsort(z, kind="stable")
        z, faces_up = z[order], up[k][inside][order]
        if not z.size:  # nothing over this point (a hole, or the world stated with another up axis)
            out.append((z, faces_up))
            continue
        # a point on an edge or a corner is in every triangle there: one surface
        first = np.flatnonzero(np.append(True, np.diff(z) > SAME_SURFACE_M))
        out.append((z[first], np.logical_or.reduceat(faces_up, first)))
    return out


def ground_along(candidates: list[tuple[np.ndarray, np.ndarray]], spacing: float, clearance: float) -> np.ndarray:
    """The ground's height (m) along a route, from the surfaces over each sample (`ground_candidates`).

    The ground is a surface that faces up: the top of a slab or a closed terrain, not its underside (which faces
    down); the ground under a tree, not its canopy's underside. At the start: the lowest surface facing up with
    at least `clearance` m of free space above it (to the next surface, facing either way). Then the surface
    facing up nearest the last ground height, if it is no steeper than 45 degrees over `spacing` m (a stone or a
    canopy beside the path is not the ground); where none is, the last height is kept. Returns (P,) float64; NaN
    before the first sample with a surface facing up (everywhere, for a mesh whose every surface faces down).
    """
    out = np.full(len(candidates), np.nan)
    g = math.nan
    for i, (z, up) in enumerate(candidates):
        if not math.isfinite(g):
            gaps = np.append(np.diff(z), np.inf)
            ground = np.flatnonzero(up & (gaps >= clearance))
            g = float(z[ground[0]]) if ground.size else math.nan
        elif up.any():
            zu = z[up]
            j = int(np.argmin(np.abs(zu - g)))
            if abs(zu[j] - g) <= max(spacing, 1e-3):
                g = float(zu[j])
        out[i] = g
    return out


@dataclass(frozen=True)
class WorldGeometry:
    """Where routes may go in a world: the xy extent of its meshes (m; None for a panorama world, unbounded) and
    the eye's z (m): `eye_height_m` above the ground under the route's start."""

    extent: tuple[float, float, float, float] | None   # x_min, y_min, x_max, y_max
    triangles: np.ndarray


def world_geometry(world: WorldSpec) -> WorldGeometry:
    tris = _triangles(cached_world(world))
    if len(tris) == 0:
        return WorldGeometry(None, tris)
    lo, hi = tris.reshape(-1, 3).min(0), tris.reshape(-1, 3).max(0)
    return WorldGeometry((float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), tris)


def eye_z(world: WorldSpec, route: Route, geometry: WorldGeometry | None = None) -> float:
    """The eye's height in the world frame (m) for `route`, after checking the route against the world:
    every point inside the world's extent and the ground under every point below the eye.
    Raises RouteError naming the first point that is outside the world or under the ground."""
    geometry = geometry or world_geometry(world)
    if geometry.extent is None:
        return world.eye_height_m
    x0, y0, x1, y1 = geometry.extent
    pts = route.points
    outside = (pts[:, 0] < x0) | (pts[:, 0] > x1) | (pts[:, 1] < y0) | (pts[:, 1] > y1)
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise RouteError(f"route point {i} ({pts[i, 0]:.3f}, {pts[i, 1]:.3f}) m is outside world {world.name!r}, "
                         f"which spans x {x0:.2f}..{x1:.2f} m, y {y0:.2f}..{y1:.2f} m (check its scale and up axis)")
    xy, _ = route.sample(CHECK_SPACING_M)
    clearance = max(GROUND_CLEARANCE_M, 2 * world.eye_height_m)
    candidates = ground_candidates(geometry.triangles, xy)
    if not any(z.size for z, _ in candidates):
        raise RouteError(f"route from ({pts[0, 0]:.3f}, {pts[0, 1]:.3f}) m has no surface under it in world "
                         f"{world.name!r}, which spans x {x0:.2f}..{x1:.2f} m, y {y0:.2f}..{y1:.2f} m (check its "
                         "scale and up axis)")
    ground = ground_along(candidates, CHECK_SPACING_M, clearance)
    if not np.isfinite(ground[0]) and candidates[0][0].size:
        raise RouteError(f"world {world.name!r} has {candidates[0][0].size} surface(s) under the route's start "
                         f"({xy[0, 0]:.3f}, {xy[0, 1]:.3f}) m and no ground: none faces up (its corners "
                         f"counter-clockwise seen from above) with {clearance:g} m free above it; a mesh wound the "
                         "other way needs its normals flipped")
    g0 = ground[0] if np.isfinite(ground[0]) else 0.0
    z = g0 + world.eye_height_m
    under = np.isfinite(ground) & (ground >= z)
    if under.any():
        i = int(np.flatnonzero(under)[0])
        raise RouteError(f"route at ({xy[i, 0]:.3f}, {xy[i, 1]:.3f}) m, {i * CHECK_SPACING_M:.2f} m along it, is "
                         f"under the ground of world {world.name!r}: ground at z = {ground[i]:.3f} m, the eye at "
                         f"{z:.3f} m ({world.eye_height_m} m above the ground at the start)")
    return float(z)


@dataclass(frozen=True)
class RouteInput:
    """A route of a route set: its name (its path relative to the set's folder, without the suffix), where it came
    from (an absolute path, or curved:SEED:LENGTH), and its release heading (rad) or None."""

    name: str
    source: str
    route: Route
    release_heading: float | None = None

    @property
    def digest(self) -> str:
        return route_digest(self.route)


def load_route(path: str | Path, name: str | None = None) -> RouteInput:
    """One route file (CSV/whitespace x_m, y_m[, heading_deg] or a trial log .h5), named `name` (default: the file's
    stem). Raises RouteError naming it."""
    from antarium.ant.route_following import route_from_log

    path = Path(path)
    name = path.stem if name is None else name
    if not path.is_file():
        raise FileNotFoundError(f"route file {str(path)!r} not found")
    if path.suffix.lower() in (".h5", ".hdf5"):
        try:
            return RouteInput(name, str(path), route_from_log(path))
        except (KeyError, ValueError, OSError) as exc:
            raise RouteError(f"{path}: not a trial log with a frames table of poses ({exc})") from None
    route, heading = read_route_file(path)
    return RouteInput(name, str(path), route, heading)


def route_files(pattern: str | Path, base: Path | None = None) -> tuple[Path, list[Path]]:
    """The set's folder and its route files: a folder (its files with a route suffix) or a glob, relative to
    `base` (`**` matches any depth of folders: routes/**/*.csv); absolute paths, sorted. The set's folder is the
    folder named, or the glob's leading part without wildcards (routes/*.csv: routes; day*/r1.csv: the spec's
    folder). Raises FileNotFoundError when it names none."""
    p = Path(pattern)
    if not p.is_absolute() and base is not None:
        p = base / p
    p = Path(os.path.abspath(p))
    if p.is_dir():
        folder = p
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in ROUTE_SUFFIXES)
    else:
        fixed = list(itertools.takewhile(lambda part: not any(c in part for c in "*?["), p.parts))
        folder = Path(*fixed) if len(fixed) < len(p.parts) else p.parent
        files = sorted(Path(f) for f in glob.glob(str(p), recursive=True) if Path(f).suffix.lower() in ROUTE_SUFFIXES)
    if not files:
        raise FileNotFoundError(f"route set {str(pattern)!r} names no route files ({', '.join(ROUTE_SUFFIXES)}); "
                                f"give a folder or a glob such as routes/*.csv")
    return folder, files


def route_name(path: Path, folder: Path) -> str:
    """A route's name: its path relative to its set's folder, without the suffix (routes/r1.csv -> r1;
    day1/r1.csv under the spec's folder -> day1/r1)."""
    return path.relative_to(folder).with_suffix("").as_posix()
