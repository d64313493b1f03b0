"""Scenes as plain data: far-field layers at infinity, named mesh objects, and the experimenter's edits.

Nothing here touches GL; `Renderer.set_scene` turns a `Scene` into GPU buffers. Units: metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from antarium.core.numbers import check_number

from .channels import CHANNELS

#: Largest texture side accepted on a mesh (larger textures are refused with a clear error).
MAX_TEXTURE_SIDE = 8192
#: Largest vertex coordinate and object position accepted (m): beyond the Earth's size is a unit or file error
#: (mesh files with coordinates of kilometres are recentred on load, `meshes.recentring`).
MAX_COORDINATE_M = 1e7
#: Largest channel gain and contrast accepted (beyond them a frame is all saturated or all dark anyway).
MAX_GAIN = 1000.0


@dataclass
class MeshData:
    """A triangle mesh in object coordinates (metres, +z up) with linear G, B, UV vertex radiances.

    vertices (V, 3) float32; faces (F, 3) uint32; colours (V, 3) float32 in [0, 1];
    uv (V, 2) float32 texture coordinates and texture (H, W, 3) float32 linear G, B, UV in [0, 1] (or (H, W, 4):
    the fourth channel a cut-out mask, 1 drawn, 0 not: fragments where it samples below 0.5 are discarded), or
    both None; vertices within MAX_COORDINATE_M of (0, 0, 0);
    double_sided: False for closed surfaces wound counter-clockwise seen from outside (their back faces
    are culled, which saves rasterising them).
    """

    vertices: np.ndarray
    faces: np.ndarray
    colours: np.ndarray
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    double_sided: bool = True

    def validate(self, name: str) -> MeshData:
        """Check shapes and values; raise ValueError naming the object. Returns self (arrays normalised)."""
        v = np.asarray(self.vertices, dtype=np.float32)
        f = np.asarray(self.faces)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) == 0:
            raise ValueError(f"mesh {name!r}: vertices must be a non-empty (V, 3) array, got shape {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise ValueError(f"mesh {name!r}: has no triangles (faces shape {f.shape})")
        if not np.all(np.isfinite(v)):
            raise ValueError(f"mesh {name!r}: vertices contain NaN or infinite values")
        if np.abs(v).max() > MAX_COORDINATE_M:
            raise ValueError(f"mesh {name!r}: vertex coordinates reach {np.abs(v).max():.3g} m; allowed: within "
                             f"{MAX_COORDINATE_M:g} m of the object's origin")
        if f.dtype.kind not in "iu" or f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"mesh {name!r}: face indices must be integers in 0..{len(v) - 1}")
        corners = v[f].astype(np.float64)
        if not np.any(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])):
            raise ValueError(f"mesh {name!r}: all {len(f)} triangle(s) have zero area (points or lines only)")
        c = np.asarray(self.colours, dtype=np.float32)
        if c.shape != (len(v), 3) or not np.all(np.isfinite(c)):
            raise ValueError(f"mesh {name!r}: colours must be a finite ({len(v)}, 3) array, got {c.shape}")
        if (self.uv is None) != (self.texture is None):
            raise ValueError(f"mesh {name!r}: texture coordinates and texture go together")
        if self.texture is not None:
            t = np.asarray(self.texture, dtype=np.float32)
            if t.ndim != 3 or t.shape[2] not in (3, 4) or min(t.shape[:2]) < 1:
                raise ValueError(f"mesh {name!r}: texture must be (H, W, 3) or (H, W, 4), got {t.shape}")
            if not (np.all(np.isfinite(t)) and t.min() >= 0.0 and t.max() <= 1.0):
                raise ValueError(f"mesh {name!r}: texture values must be in [0, 1], got {np.nanmin(t):g} to "
                                 f"{np.nanmax(t):g}")
            if max(t.shape[:2]) > MAX_TEXTURE_SIDE:
                raise ValueError(f"mesh {name!r}: texture of {t.shape[1]}x{t.shape[0]} pixels is larger than "
                                 f"{MAX_TEXTURE_SIDE} pixels on a side")
            uv = np.asarray(self.uv, dtype=np.float32)
            if uv.shape != (len(v), 2) or not np.all(np.isfinite(uv)):
                raise ValueError(f"mesh {name!r}: texture coordinates must be a finite ({len(v)}, 2) array")
            self.uv, self.texture = uv, t
        self.vertices, self.faces, self.colours = v, f.astype(np.uint32), np.clip(c, 0.0, 1.0)
        return self

    @property
    def n_triangles(self) -> int:
        return len(self.faces)


@dataclass
class SceneObject:
    """A named mesh placed in the world: position (3,) m, yaw about +z (rad), uniform scale."""

    mesh: MeshData
    position: tuple = (0.0, 0.0, 0.0)
    yaw: float = 0.0
    scale: float = 1.0

    def __post_init__(self):
        p = np.asarray(self.position, dtype=np.float64)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or np.abs(p).max() > MAX_COORDINATE_M:
            raise ValueError(f"object position must be 3 finite numbers (m) within {MAX_COORDINATE_M:g} m of "
                             f"(0, 0, 0), got {self.position!r}")
        if not np.isfinite(self.yaw):
            raise ValueError(f"object yaw must be finite, got {self.yaw!r}")
        if not (np.isfinite(self.scale) and self.scale > 0):
            raise ValueError(f"object scale must be a positive number, got {self.scale!r}")
        self.position = tuple(float(x) for x in p)

    def world_vertices(self) -> np.ndarray:
        """(V, 3) float32 vertices in world coordinates."""
        return self.to_world(self.mesh.vertices)

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """(P, 3) object-space points (m) -> (P, 3) float32 world coordinates (scale, yaw, then position)."""
        c, s = np.cos(self.yaw), np.sin(self.yaw)
        rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        v = np.asarray(points, dtype=np.float64) * self.scale
        return (v @ rot.T + np.asarray(self.position)).astype(np.float32)


@dataclass
class Scene:
    """A world: `far` layers at infinity (each composited over the ones before it by its alpha, the first over
    black) and
    named `objects`. Edits: `rotation` of the whole scene about the vertical through `pivot` (x, y) m;
    `channel_gain` (G, B, UV); `swap_green_blue`; `lowpass_deg` (angular low-pass cut-off period, degrees)
    and `contrast` (scaling of deviations from the frame's mean, per channel).
    """

    far: list = field(default_factory=list)
    objects: dict = field(default_factory=dict)
    name: str = "scene"
    rotation: float = 0.0
    pivot: tuple = (0.0, 0.0)
    channel_gain: tuple = (1.0, 1.0, 1.0)
    swap_green_blue: bool = False
    lowpass_deg: float | None = None
    contrast: float = 1.0

    def __post_init__(self):
        if not self.far:
            raise ValueError(f"scene {self.name!r} needs at least one far-field layer (sky, panorama, stimulus)")
        for name, obj in self.objects.items():
            if not isinstance(obj, SceneObject):
                raise ValueError(f"scene object {name!r} must be a SceneObject, got {type(obj).__name__}")
            obj.mesh.validate(name)
        self.rotation = check_number("scene rotation (rad)", self.rotation)
        if not isinstance(self.swap_green_blue, (bool, np.bool_)):
            raise ValueError(f"swap_green_blue must be true or false, got {repr(self.swap_green_blue)[:60]}")
        self.swap_green_blue = bool(self.swap_green_blue)
        check_channel_gain(self.channel_gain)
        check_lowpass(self.lowpass_deg)
        check_contrast(self.contrast)

    @property
    def n_triangles(self) -> int:
        return sum(o.mesh.n_triangles for o in self.objects.values())

    @property
    def sky(self):
        """The first `Sky` layer (polarisation source), or None."""
        from .sky import Sky

        return next((layer for layer in self.far if isinstance(layer, Sky)), None)

    @property
    def yaw_rate(self) -> float:
        """Rotation rate (rad/s) of the far field about the vertical, when all its motion is such a rotation."""
        rates = {float(layer.yaw_rate) for layer in self.far}
        return rates.pop() if len(rates) == 1 else 0.0

    @property
    def far_time_varying(self) -> bool:
        rates = {float(layer.yaw_rate) for layer in self.far}
        return any(layer.time_varying for layer in self.far) or len(rates) > 1

    def supersample(self, step: float) -> int:
        """Sub-samples per axis that averaging the far field over cells of `step` (rad) needs."""
        return max(layer.supersample(step) for layer in self.far)

    def rim_samples(self, centres: np.ndarray, step: float, cell_samples, t: float = 0.0) -> tuple:
        """The cells that a sky's sun rim crosses (`Sky.rim_cells`) and the far field sampled finely in them, for
        averaging those cells apart: a sun about a cell wide, averaged with `supersample(step)` sub-samples, would be
        over- or under-counted by up to a cell.

        centres: (N, 3) unit cell-centre directions; step: the cells' largest width (rad); cell_samples(idx, sub):
        (K, sub, sub, 3) unit directions of evenly spaced sub-samples (the cell split into sub x sub equal parts, one
        at each part's centre) in the cells `idx` ((K,) int64). Returns ((K,) int64 indices into centres,
        (K, sub * sub, 4) float32 `evaluate_far` at time t (s) at their sub-samples), sub = `Sky.rim_supersample`.
        """
        from .sky import Sky

        skies = [layer for layer in self.far if isinstance(layer, Sky)]
        if not skies:  # no sun: nothing to refine (the per-frame far texture of a sky-less scene pays nothing)
            return np.empty(0, dtype=np.int64), np.empty((0, 1, 4), dtype=np.float32)
        hit = np.zeros(len(centres), dtype=bool)
        for sky in skies:
            hit |= sky.rim_cells(centres, step)
        idx = np.flatnonzero(hit)
        sub = max((sky.rim_supersample(step) for sky in skies), default=1)
        d = cell_samples(idx, sub).reshape(-1, 3)
        return idx, self.evaluate_far(d, t).reshape(len(idx), sub * sub, 4)

    def evaluate_far(self, d: np.ndarray, t: float = 0.0) -> np.ndarray:
        """(N, 4) float32 [G, B, UV, polarised UV] of the far field at (N, 3) world directions, time t (s).

        When the far field only rotates (`yaw_rate`), this is its state at t = 0; the renderer rotates it.
        """
        out = np.zeros((len(d), 4), dtype=np.float32)  # black under the first layer (a transparent one: bars alone)
        for layer in self.far:
            v = layer.evaluate(d, t)
            a = v[:, 4:5]
            out = out * (1.0 - a) + v[:, :4] * a
        return out


def check_channel_gain(gain) -> tuple:
    """(G, B, UV) gains as 3 floats in [0, MAX_GAIN]."""
    if isinstance(gain, (str, bytes)) or np.shape(gain) != (3,):
        raise ValueError(f"channel gains must be 3 numbers in [0, {MAX_GAIN:g}] for {CHANNELS}, got {gain!r}")
    return tuple(check_number(f"{c} channel gain", g, 0.0, MAX_GAIN) for c, g in zip(CHANNELS, gain, strict=True))


def check_lowpass(cutoff_deg, footprint_deg: float | None = None) -> None:
    """Low-pass cut-off period in (0, `footprint.max_lowpass_deg(footprint_deg)`] degrees, or None (off): a wider
    one would widen an LED acceptance of `footprint_deg` (default: the LED pitch) past `footprint.MAX_FWHM_DEG`."""
    from .footprint import LED_PITCH_DEG, max_lowpass_deg

    name = "lowpass_deg (low-pass cut-off period, degrees)"
    if cutoff_deg is None:
        return
    high = max_lowpass_deg(LED_PITCH_DEG if footprint_deg is None else footprint_deg)
    if check_number(name, cutoff_deg, 0.0, high) == 0:
        raise ValueError(f"{name} must be > 0 (or None: off), got {cutoff_deg!r}")


def check_contrast(contrast) -> float:
    """Contrast in [0, MAX_GAIN] (1 = unchanged)."""
    return check_number("contrast (1 = unchanged)", contrast, 0.0, MAX_GAIN)
