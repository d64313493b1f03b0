"""`Renderer`: a scene and an eye pose in, one LED frame out, through a cube map rendered off-screen.

Per frame: six 90° views from the eye into one (6N x N) 16-bit atlas (far field as background, then the
meshes, each view drawing only the chunks inside its frustum), one read-back into a preallocated array,
the sparse footprint matrix (texels -> LEDs, a compiled loop) and the 16-bit conversion. The cube is aligned
with the dome (yawed with the ant), so the matrix is fixed and cached; far-field content lives in a
world-aligned cube texture sampled by the background pass. Scenes without meshes take the fast path of
`farfield`: no GL per frame, a table lookup per LED.
"""

from __future__ import annotations

import collections
import functools
import math
import os
import threading
import time

import numpy as np

from antarium.core.numbers import as_real, check_number
from antarium.core.pose import Pose
from antarium.geometry.constants import N_PANELS, N_PIXELS, UV_PER_PANEL

from . import cubemap, footprint, shaders
from .far_layer import builder_nice
from .farfield import FarFieldTable
from .footprint import LED_PITCH_DEG, footprint_fwhm, lowpass_fwhm  # noqa: F401 (lowpass_fwhm: this module's API)
from .gl import create_context, describe
from .gpu_path import ATLAS, FAR_ONLY, OVER_FAR, GpuFramePath, check_path, default_path
from .meshbuffers import MeshBuffers
from .output import FrameConverter, polariser_angles
from .scene import Scene, check_channel_gain, check_contrast, check_lowpass

# LED_PITCH_DEG: LED pitch of the dome (degrees); the default footprint width and face size derive from it.
#: Largest texel (at a face centre) as a fraction of the LED pitch: 2 atan(1/N) <= 0.4 * 1.5 deg -> N = 192.
TEXEL_FRACTION = 0.4


def default_face_size(pitch_deg: float = LED_PITCH_DEG, fraction: float = TEXEL_FRACTION) -> int:
    """Smallest multiple of 32 whose largest texel is at most `fraction` of the LED pitch."""
    n = 1.0 / math.tan(math.radians(fraction * pitch_deg) / 2)
    return int(math.ceil(n / 32.0) * 32)


DEFAULT_FACE_SIZE = default_face_size()
#: cube face sides a Renderer accepts: at least MIN_FACE_SIZE (the mipmap levels a low-pass samples stop at 16) and
#: at least what the LED footprint needs (`smallest_face_size`)
MIN_FACE_SIZE, MAX_FACE_SIZE = 16, 2048


def smallest_face_size(footprint_deg: float = LED_PITCH_DEG) -> int:
    """Smallest face side a Renderer with LED footprint `footprint_deg` accepts: every LED must see a texel centre
    within its footprint (`footprint.min_face_size`: 55 for the 1.5 degree pitch)."""
    return max(MIN_FACE_SIZE, footprint.min_face_size(footprint_deg))

#: default face size of the near meshes when a far layer carries the rest (`far_layer`)
NEAR_FACE_SIZE = 96
#: a time-varying far field is drawn from a texture rebuilt every frame at one sample a texel: its finest period must
#: span this many of the texture's largest texels, 2 atan(1 / far_face_size) (measured: LED error against the same
#: pattern standing still, max over the dome, under 0.02 from 6.7 texels at far faces 64 and 96, 0.04 at 4.5)
DRIFT_TEXELS = 7
#: texels across the footprint's FWHM below which a wider footprint samples a coarser mipmap level
TEXELS_PER_FWHM = 2.5


def mip_face_size(n: int) -> int:
    """The face side (texels) a Renderer uses for a requested side `n`: `n` rounded up to the next m * 2**k with m in
    16..31, so that each mipmap level a low-pass samples (`Renderer._sampling`: down to a level of 16..31 texels a
    face) halves every face exactly; an odd side would sample level 0 only, thousands of weights per LED (55 -> 56,
    150 -> 152; 2**k and multiples of 8 up to 248 stay)."""
    k = max(0, int(n).bit_length() - 5)
    return -(-int(n) >> k) << k


def _default_face_size(face_size: int | None, far_layer: str) -> int:
    """The requested face side, or the default for a `far_layer` mode ("off", "sync" or "async")."""
    return (DEFAULT_FACE_SIZE if far_layer == "off" else NEAR_FACE_SIZE) if face_size is None else face_size


def _check_face_size(label: str, value, footprint_deg: float | None = None) -> int:
    """`value` as an int face side, from `smallest_face_size(footprint_deg)` (None: MIN_FACE_SIZE) to MAX_FACE_SIZE;
    ValueError otherwise."""
    lo = MIN_FACE_SIZE if footprint_deg is None else smallest_face_size(footprint_deg)
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= MAX_FACE_SIZE:
        why = "" if lo == MIN_FACE_SIZE else (f" (a smaller face leaves LEDs of a {footprint_deg:g} degree "
                                              "footprint between texels: raise face_size)")
        raise ValueError(f"{label} must be an integer in {lo}..{MAX_FACE_SIZE}{why}, got {value!r}")
    return int(value)


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _gl_current(method):
    """Run a Renderer method with its own GL context current, so that several renderers can share a thread."""

    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        if self._released:
            raise RuntimeError("renderer was released")
        with self.ctx:
            return method(self, *args, **kwargs)

    return wrapper


def _check_time(t) -> float:
    """Stimulus time t (s) as a float; ValueError unless finite."""
    return check_number("time t (s)", t)


def _check_pose(pose) -> Pose:
    if isinstance(pose, Pose):
        return pose
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        raise ValueError(f"pose must be an antarium.core.pose.Pose or (x, y, z, heading), got {pose!r}") from None
    if len(values) != 4:
        raise ValueError(f"pose must have 4 values (x, y, z in m, heading in rad), got {pose!r}")
    return Pose(*values)


class Renderer:
    """Off-screen cube-map renderer for the dome. Use it from the thread that built it: its EGL context is
    current there only (the server builds it in the frame loop's thread and runs commands there). Each method
    makes its context current, so several renderers can share a thread.

    dome: `antarium.geometry.Dome` (default: `load_dome()`); face_size: cube face side in texels (default
    from the LED pitch); footprint_deg: FWHM of each LED's acceptance; brightness: global drive scale
    in [0, 1]; near, far: clip planes (m); far_face_size: side of the far-field cube texture (16..2048 texels,
    default face_size); chunk_size: cell (m, > 0) of the culling grid of large meshes; lod_texels: level-of-detail
    bound in texels, twice the most a merged vertex moves (0: full detail always); clock: an `antarium.core.clock`
    clock for drifting stimuli when `render` gets no time;
    fast_far_field: take static far fields from a footprint-integrated table (`farfield`) instead of drawing
    them into the cube map every frame; far_layer: "off", "sync" or "async": draw only the meshes within
    `near_radius` (m) every frame, the rest from a layer rendered from a recent eye position while its
    parallax error stays under `far_layer_error_deg` (`far_layer`; face_size then defaults to
    NEAR_FACE_SIZE and the layer is rendered at `layer_face_size`, default DEFAULT_FACE_SIZE); path: "gpu"
    (sampling, conversion and VIDEO packing in compute shaders, `gpu_path`), "cpu" (numba loops) or None
    (chosen from the GL renderer string: "cpu" on a software driver such as llvmpipe); far_layer "auto": "off" on
    the GPU path, "async" on the CPU path.
    """

    def __init__(self, dome=None, face_size: int | None = None, footprint_deg: float = LED_PITCH_DEG,
                 brightness: float = 1.0, near: float = 1e-3, far: float = 1e3, far_face_size: int | None = None,
                 chunk_size: float = 1.0, lod_texels: float = 1.0, clock=None, fast_far_field: bool = True,
                 far_layer: str = "off", near_radius: float = 2.0, far_layer_error_deg: float = 0.5,
                 layer_face_size: int | None = None, path: str | None = None):
        from .far_layer import MODES

        path = check_path(path)
        if far_layer not in (*MODES, "auto"):
            raise ValueError(f"far_layer must be one of {', '.join(MODES)} or auto, got {far_layer!r}")
        if not (math.isfinite(as_real(near_radius)) and near_radius > 0):
            raise ValueError(f"near_radius must be a positive number of metres, got {near_radius!r}")
        if not (math.isfinite(as_real(far_layer_error_deg)) and 0 < far_layer_error_deg <= 5):
            raise ValueError(f"far_layer_error_deg must be in (0, 5], got {far_layer_error_deg!r}")
        if not (math.isfinite(as_real(chunk_size)) and chunk_size > 0):
            raise ValueError(f"chunk_size must be a positive number of metres, got {chunk_size!r}")
        if far_face_size is not None:
            _check_face_size("far_face_size", far_face_size)
        if not (math.isfinite(as_real(footprint_deg)) and 0 < footprint_deg < footprint.MAX_FWHM_DEG):
            raise ValueError(f"footprint_deg must be in (0, {footprint.MAX_FWHM_DEG:g}), got {footprint_deg!r}")
        if face_size is not None or far_layer != "auto":  # else the default depends on the path: checked below
            _check_face_size("face_size", _default_face_size(face_size, far_layer), footprint_deg)
        m = DEFAULT_FACE_SIZE if layer_face_size is None else layer_face_size
        _check_face_size("layer_face_size", m)
        if not (0 < as_real(near) < as_real(far) < math.inf):
            raise ValueError(f"clip planes must satisfy 0 < near < far, got near={near!r}, far={far!r}")
        if not (math.isfinite(as_real(lod_texels)) and lod_texels >= 0):
            raise ValueError(f"lod_texels must be a non-negative number, got {lod_texels!r}")
        if dome is None:
            from antarium.geometry import load_dome

            dome = load_dome()
        # every check is made: the GL context comes last, and is released again if anything after it fails
        self._released = False
        self.ctx = create_context()
        try:
            self._set_up(dome, face_size, footprint_deg, brightness, near, far, far_face_size, chunk_size,
                         lod_texels, clock, fast_far_field, far_layer, near_radius, far_layer_error_deg, m, path)
        except BaseException:
            self._released = True
            self.ctx.release()
            raise

    def _set_up(self, dome, face_size, footprint_deg, brightness, near, far, far_face_size, chunk_size, lod_texels,
                clock, fast_far_field, far_layer, near_radius, far_layer_error_deg, layer_face_size, path) -> None:
        """`__init__` past its checks, in the renderer's own (current) GL context."""
        # the renderer's own context tells the path (a probe context of its own made the first frame's helper
        # thread start late)
        path = path or default_path(self.ctx.info["GL_RENDERER"])
        if far_layer == "auto":  # a GPU draws every mesh every frame; a CPU needs the far layer
            far_layer = "off" if path == "gpu" else "async"
        n = mip_face_size(_check_face_size("face_size", _default_face_size(face_size, far_layer), footprint_deg))
        self.far_layer_mode, self.near_radius = far_layer, float(near_radius)
        self.far_layer_error = math.radians(far_layer_error_deg)
        self.layer_face_size = int(layer_face_size)
        self.dome = dome
        self.face_size = n
        self.far_face_size = n if far_face_size is None else int(far_face_size)
        self.footprint_deg = float(footprint_deg)
        self.near, self.far = float(near), float(far)
        self.chunk_size = float(chunk_size)
        self.fast_far_field = bool(fast_far_field)
        #: level-of-detail error bound (rad): a fraction of the largest texel
        self.lod_texels = float(lod_texels)
        #: the async far-layer builders' nice value, set by this (the frame loop's) thread's scheduling
        self.builder_nice = builder_nice()
        self.lod_angle = math.radians(lod_texels * cubemap.largest_texel_deg(self.face_size))
        if clock is None:
            from antarium.core.clock import MonotonicClock

            clock = MonotonicClock()
        self.clock = clock
        self._directions = np.ascontiguousarray(dome.directions, dtype=np.float64)
        uv = np.asarray(dome.uv_index)
        self._uv_dirs = self._directions[uv]
        self._uv_axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
        self._convert = FrameConverter(np.asarray(dome.gain), brightness)
        self._channel = np.where(self._convert.is_uv, 2, 0).astype(np.int64)

        self._setup_gl()
        #: GL renderer and version, and the per-frame path taken after the cube map ("gpu" or "cpu")
        self.gl_renderer = describe(self.ctx)
        self.path = path
        self._gpu = None
        if self.path == "gpu":
            try:
                with self.ctx:
                    self._gpu = GpuFramePath(self.ctx)
            except Exception as exc:
                raise RuntimeError(f"the gpu render path needs OpenGL 4.3 compute shaders, which {self.gl_renderer} "
                                   f"does not give ({exc}); use path 'cpu'") from exc
            self._gain_version = None
        self._busy_s = 1e-3  # the longest recent busy pass (s), decaying from a safe first guess
        from .kernels import warm_up

        warm_up()
        self._texels = np.empty((6 * n * n, 4), dtype=np.uint16)
        self._pairs = np.empty((N_PIXELS, 2), dtype=np.float32)
        self._far_pairs = np.empty((N_PIXELS, 2), dtype=np.float32)
        self._fwhm = None
        self._kernel_matrix = None
        self.scene: Scene | None = None
        self._meshes: MeshBuffers | None = None
        self._table = None
        self._layer = None
        self._helper = None
        #: uploads of prepared scenes that will not be shown, discarded in other threads; released in the GL one
        self._discarded: collections.deque = collections.deque()
        #: GL objects of the scene shown before a `set_scene(..., retire=True)`, released one a call (`release_retired`)
        self._retired: collections.deque = collections.deque()
        #: frames drawn with the far layer, and in full (no usable layer: start-up, edits, a jump of the eye)
        self.layer_frames = self.full_frames = 0
        #: whether the last frame drew every mesh (no far layer in use): the slow path
        self.last_full_render = False
        #: pieces of work the helper thread had not started when the frame needed them (done by the caller)
        self.helper_misses = 0
        self._t0 = 0.0
        self._last_q = np.eye(3)
        self.last_timings = {"render": 0.0, "sample": 0.0, "convert": 0.0}
        self._set_footprint(None)

    # ----------------------------------------------------------------------------------------- GL set-up
    def _setup_gl(self) -> None:
        import moderngl

        ctx, n = self.ctx, self.face_size
        self._depth = ctx.depth_renderbuffer((n, 6 * n))
        #: (atlas, framebuffer) per kind: False the 16-bit normalised one, True the float one (`_use_atlas`)
        self._targets = {}
        #: float read-back arrays of the float atlas, by texel count (one per mipmap level used)
        self._float_texels = {}
        self._use_atlas(False)
        self._bg_prog = ctx.program(vertex_shader=shaders.FULLSCREEN_VS, fragment_shader=shaders.BACKGROUND_FS)
        self._bg_prog["far_tex"].value = 0
        self._bg_prog["face_size"].value = float(n)
        self._bg_vao = ctx.vertex_array(self._bg_prog, [])
        self._mesh_prog = ctx.program(vertex_shader=shaders.MESH_VS, fragment_shader=shaders.MESH_FS)
        self._mesh_prog["textures"].value = 1
        self._far_tex = None
        self._proj = cubemap.projection_matrix(self.near, self.far)
        self._mgl = moderngl

    def _use_atlas(self, bright: bool) -> None:
        """Draw into the float atlas (`bright`) or the 16-bit normalised one (made when first needed; shared depth).

        A far field brighter than 1 somewhere (a sun above 1) goes into the float one: the normalised one would clip
        each texel to 1 before the footprint averages it, where the far-field table averages first and clips after
        (`render` and the GPU path's sample pass then clip each LED's average to 1, as the table's quantisation does).
        """
        if bright not in self._targets:
            n = self.face_size
            atlas = self.ctx.texture((n, 6 * n), 4, dtype="f4" if bright else "nu2")
            # Its whole mipmap chain exists before the framebuffer takes level 0: a first glGenerateMipmap on a
            # texture without one re-allocates its storage (Mesa), after which the framebuffer drew into the old
            # level 0 and every low-passed frame but the first showed the first one's content.
            atlas.build_mipmaps()
            self._targets[bright] = (atlas, self.ctx.framebuffer([atlas], self._depth))
        self._atlas, self._fbo = self._targets[bright]
        self._bright = bright

    def _make_far_texture(self, scene: Scene, t: float = 0.0, supersample: int | None = None):
        """World-aligned float16 cube texture of the far field, each texel the mean of supersample^2 points
        (default: as many as the scene's finest detail needs; more where a sun's rim crosses it,
        `Scene.rim_samples`); its `extra` is its largest value."""
        nf = self.far_face_size
        if supersample is None:
            supersample = scene.supersample(2.0 / nf)
        m = nf * supersample
        d = cubemap.gl_cube_directions(m).reshape(-1, 3)
        v = scene.evaluate_far(d, t).reshape(6, nf, supersample, nf, supersample, 4).mean(axis=(2, 4))
        c = cubemap.texel_coordinates(nf)

        def texel_samples(idx: np.ndarray, n: int) -> np.ndarray:
            face, row, col = np.unravel_index(idx, (6, nf, nf))
            o = (np.arange(n) - (n - 1) / 2) * (2.0 / (nf * n))
            return cubemap.gl_face_directions(face[:, None, None], c[row, None, None] + o[:, None],
                                              c[col, None, None] + o)

        centres = d if supersample == 1 else cubemap.gl_cube_directions(nf).reshape(-1, 3)
        idx, fine = scene.rim_samples(centres, 2.0 / nf, texel_samples, t)
        v.reshape(-1, 4)[idx] = fine.mean(axis=1)
        data = np.ascontiguousarray(v, dtype=np.float16)
        tex = self.ctx.texture_cube((nf, nf), 4, data.tobytes(), dtype="f2")
        tex.filter = (self._mgl.LINEAR, self._mgl.LINEAR)
        tex.extra = float(v.max())
        return tex

    def smallest_drift_period_deg(self) -> float:
        """Shortest period (degrees) a time-varying far field may have here: DRIFT_TEXELS largest texels of the far
        texture it is drawn from, rebuilt every frame at one sample a texel (finer ones alias into false patterns)."""
        return DRIFT_TEXELS * cubemap.largest_texel_deg(self.far_face_size)

    def _check_drift(self, scene: Scene) -> None:
        """ValueError, one line, for a far field redrawn every frame (`Scene.far_time_varying`) whose moving layers
        (gratings: drifting in any direction but azimuth, or drums turning at another rate than a layer beside them)
        have a period finer than `smallest_drift_period_deg`."""
        if not scene.far_time_varying:
            return
        finest = min((layer.period for layer in scene.far if layer.time_varying or layer.yaw_rate), default=math.inf)
        smallest = self.smallest_drift_period_deg()
        if math.degrees(finest) < smallest:
            raise ValueError(f"a drifting grating's period must be at least {smallest:.2f} deg on this renderer (its "
                             f"far texture, far_face_size {self.far_face_size}, is redrawn every frame at one sample a "
                             f"texel; finer would alias), got {math.degrees(finest):g} deg")

    def footprint_fwhm_for(self, lowpass_deg) -> float:
        """FWHM (rad) of the LED acceptance widened by an angular low-pass of `lowpass_deg` (None: none)."""
        return footprint_fwhm(self.footprint_deg, lowpass_deg)

    def _set_footprint(self, lowpass_deg) -> None:
        """The LED acceptance, widened by an angular low-pass; its sampling matrix is made when first needed. A
        low-pass too wide for this renderer's footprint (`check_lowpass`) raises ValueError and changes nothing."""
        check_lowpass(lowpass_deg, self.footprint_deg)
        fwhm = self.footprint_fwhm_for(lowpass_deg)
        if fwhm != self._fwhm:
            self._fwhm, self._kernel_matrix = fwhm, None

    def _sampling(self) -> tuple:
        """(atlas level, CSR arrays) of the footprint matrix, loaded or built on first use.

        Wide footprints (a low-pass) are sampled from a mipmap level of the atlas that still has
        TEXELS_PER_FWHM texels across the FWHM (and 16 or more across a face), which keeps the matrix at a few
        hundred weights per LED at most (docs/rendering.md).
        """
        if self._kernel_matrix is None:
            texel = math.radians(cubemap.largest_texel_deg(self.face_size))
            level = 0
            while ((self.face_size >> (level + 1)) >= 16  # each level halves the faces exactly (`mip_face_size`)
                   and self._fwhm / (texel * (2 << level)) >= TEXELS_PER_FWHM):
                level += 1
            n = self.face_size >> level
            m = footprint.cached_matrix(self._directions, n, self._fwhm)
            self.sampling_weights = m.nnz
            # weights in radiance per 16-bit texel unit, for the compiled sampling loop
            arrays = (m.indptr.astype(np.int64), m.indices.astype(np.int32), (m.data / 65535.0).astype(np.float32))
            texels = self._texels if level == 0 else np.empty((6 * n * n, 4), dtype=np.uint16)
            self._kernel_matrix = (level, texels, *arrays)
        return self._kernel_matrix

    @property
    def footprint_fwhm(self) -> float:
        """Current footprint FWHM (rad): the LED acceptance widened by any angular low-pass."""
        return self._fwhm

    # ------------------------------------------------------------------------------------------ scenes
    @_gl_current
    def set_scene(self, scene, retire: bool = False) -> Scene:
        """Load a `Scene`, a scene name, a spec dict, a file path, or a `PreparedScene` (`prepare_scene`, made in
        another thread: only the GL uploads run here). On any error the previous scene stays.

        retire: the previous scene's GL objects are not released here but kept for `release_retired`, one a call (a
        frame loop's idle time: releasing a large buffer took the NVIDIA driver up to 10 ms)."""
        from .library import build_scene
        from .prepared import PreparedScene, SceneSettings

        self._release_discarded()
        prepared = scene if isinstance(scene, PreparedScene) else None
        far_tex = meshes = None
        try:
            if prepared is None:
                prepared = SceneSettings.of(self).build(scene if isinstance(scene, Scene) else build_scene(scene))
            new, table = prepared.scene, prepared.table
            self._check_drift(new)
            self._set_footprint(new.lowpass_deg)
            if table is None:
                far_tex = self._make_far_texture(new)
            if new.objects:
                meshes = MeshBuffers(self.ctx, self._mesh_prog, new.objects, self.chunk_size, self.lod_angle,
                                     arrays=prepared.arrays, upload=prepared.upload, gpu_cull=self._gpu is not None)
                prepared.upload = None  # the meshes own its buffers now
            prepared.arrays = None
        except BaseException:
            for res in (far_tex, meshes, prepared):
                if res is not None:
                    res.release()
            self._set_footprint(self.scene.lowpass_deg if self.scene else None)
            raise
        old_tex, old_meshes = self._far_tex, self._meshes
        self._far_tex, self._meshes, self._table, self.scene = far_tex, meshes, table, new
        if prepared.gpu_table is not None:  # the GPU path's table, staged with the meshes: adopted, not uploaded
            self._gpu.adopt_table(prepared.gpu_table.finish())
            prepared.gpu_table = None
        prepared.closed = True
        self._drop_gpu_table()
        self._convert.configure(channel_gain=new.channel_gain, swap_green_blue=new.swap_green_blue,
                                contrast=new.contrast)
        self._t0 = self.clock.now()
        old = [old_tex] if old_tex is not None else []
        old += old_meshes.detach() if old_meshes is not None else []
        if retire:
            self._retired.extend(old)
        else:
            for res in old:
                res.release()
        if prepared is not None and prepared.layer is not None:
            old_layer, self._layer, prepared.layer = self._layer, prepared.layer, None
            if old_layer is not None:  # an async layer's process may take a while to stop: not in this thread
                threading.Thread(target=old_layer.release, name="far-layer-release", daemon=True).start() \
                    if old_layer.mode == "async" else old_layer.release()
        else:
            self._restart_layer()
        return new

    @_gl_current
    def upload_step(self, prepared) -> bool:
        """Upload one slice of a prepared scene's meshes, then on the GPU path of its far-field table
        (`meshbuffers.UPLOAD_SLICE_BYTES`), so that `set_scene` has only what is left; True once nothing is (or the
        scene was shown or released meanwhile). GL thread: call it in the idle end of frames (`FrameLoop.when_idle`)."""
        from .meshbuffers import StagedUpload

        self._release_discarded()
        arrays, table = prepared.arrays, prepared.table
        if arrays is not None:
            upload = prepared.staged("upload", lambda: StagedUpload(self.ctx, arrays, discard=self._discarded.append))
            if upload is None:  # shown or released
                return True
            if not upload.step():
                return False
        if self._gpu is None or table is None:
            return True
        staged = prepared.staged("gpu_table", lambda: self._gpu.stage_table(table, discard=self._discarded.append))
        return staged is None or staged.step()

    @property
    def retired(self) -> int:
        """GL objects of scenes shown before, left for `release_retired`."""
        return len(self._retired)

    @_gl_current
    def release_retired(self) -> int:
        """Release one GL object of a scene shown before (`set_scene(..., retire=True)`); returns how many are left.
        GL thread."""
        if self._retired:
            self._retired.popleft().release()
        return len(self._retired)

    def _release_discarded(self) -> None:
        """Release the GL buffers of uploads discarded by other threads (in this, the GL thread)."""
        while self._discarded:
            self._discarded.popleft().release()

    def use_clock(self, clock) -> None:
        """Render on `clock` from now on, its current time the scene's start (a renderer reused for a new run)."""
        self.clock = clock
        self._t0 = clock.now()

    def prepare_scene(self, scene, pose=None, timeout_s: float | None = None):
        """`set_scene`'s work but the GL uploads, for any thread (see `renderers.prepared`); pose: a callable
        giving the eye's pose now, to wait for the scene's far layer there."""
        from .prepared import LAYER_WAIT_S, prepare_scene

        prepared = prepare_scene(self, scene, pose, LAYER_WAIT_S if timeout_s is None else timeout_s)
        try:  # refused here, in the preparing thread, rather than at the swap
            self._check_drift(prepared.scene)
        except ValueError:
            prepared.release()
            raise
        return prepared

    def await_layer(self, prepared, pose, timeout_s: float | None = None) -> None:
        """Wait until a prepared scene's far layer is fresh at the eye of `pose()` (see `prepared.await_layer`):
        the last step before its swap, after the uploads. Any thread."""
        from .prepared import LAYER_WAIT_S, await_layer

        await_layer(prepared, lambda: self._scene_eye(prepared.scene, pose()),
                    LAYER_WAIT_S if timeout_s is None else timeout_s)

    def prepare_far(self, far):
        """`set_far`'s work but the GL uploads, for any thread: a `PreparedFar` with the current scene's far field
        replaced by the layers `far` (its table). Raises ValueError for layers a scene cannot have."""
        from .prepared import PreparedFar, SceneSettings

        scene = self._require_scene()
        # the far field alone: the objects are not read here (the loop's thread may be editing them meanwhile)
        trial = Scene(far=list(far), name=scene.name)
        fwhm = self._fwhm
        table = FarFieldTable.of_scene(trial, self._directions, fwhm) if SceneSettings.of(self).table_ok(trial) \
            else None
        return PreparedFar(scene, trial.far, fwhm, table)

    def prefetch_far(self, pose, prepared) -> None:
        """A `set_far(prepared)` about to come, the eye at `pose`: the async far layer over the new far field is
        built meanwhile, so that the change shows with its layer from its first frame (`edit_ready`); withdrawn
        with `withdraw_far` if the change is not made. Rendering thread."""
        if self._layer is not None and prepared.table is not None and self._current(prepared):
            self._layer.edit_ahead(("far", prepared.table), self._scene_eye(prepared.scene, _check_pose(pose)))

    def withdraw_far(self, prepared) -> None:
        """A prefetched far field that will not be shown: the far layer's builder goes back to the current one.
        Rendering thread."""
        edit = ("far", prepared.table)
        if self._layer is not None and prepared.table is not None and (undo := self._undo(edit)) is not None:
            self._layer.withdraw(edit, undo)

    def _current(self, prepared) -> bool:
        """Whether a `PreparedFar` was made for the scene and footprint now in use."""
        return prepared.scene is self.scene and prepared.fwhm == self._fwhm

    @_gl_current
    def set_far(self, far) -> None:
        """Replace the current scene's far-field layers (a list, or `prepare_far`'s result), keeping its objects and
        every edit made to it: only the far field's table (or cube texture) and the far layer's field change. A
        result prepared for another scene or footprint is prepared again here. On error the far field stays."""
        from .prepared import PreparedFar

        scene = self._require_scene()
        if not isinstance(far, PreparedFar) or not self._current(far):
            if isinstance(far, PreparedFar):
                self.withdraw_far(far)
                far = far.far
            far = self.prepare_far(far)
        self._check_drift(Scene(far=far.far, name=scene.name))
        had_table = self._table is not None
        far_tex = self._make_far_texture(Scene(far=far.far, name=scene.name)) if far.table is None else None
        old_tex, self._far_tex = self._far_tex, far_tex
        scene.far, self._table = far.far, far.table
        self._drop_gpu_table()
        if old_tex is not None:
            old_tex.release()
        if self._layer is not None and had_table and far.table is not None:
            self._layer_edit(("far", far.table))
        else:
            self._restart_layer()

    def _drop_gpu_table(self) -> None:
        """The GPU path's copy of a far-field table the scene no longer has is released (a new one is uploaded
        by the first frame that looks one up)."""
        if self._gpu is not None and self._table is None:
            self._gpu.drop_table()

    def _restart_layer(self) -> None:
        """A new far layer for the current scene and footprint (none when off, or nothing to split)."""
        from .far_layer import FarLayer
        from .prepared import SceneSettings

        if self._layer is not None:
            self._layer.release()
            self._layer = None
        scene = self.scene
        args = SceneSettings.of(self).layer_args(scene, self._table)
        if args is not None:
            self._layer = FarLayer(self.far_layer_mode, self.ctx, dict(scene.objects), self._table, *args,
                                   lambda eye, radius: self._meshes.near_chunks(eye, radius), nice=self.builder_nice)

    @_gl_current
    def wait_far_layer(self, pose, timeout_s: float = 60.0) -> bool:
        """Block until a far layer usable at `pose` is in (at once when there is no far layer); False on timeout
        or a builder error. Call before the first frame, so that the experiment does not start with frames
        drawn in full."""
        scene = self._require_scene()
        if self._layer is None:
            return True
        eye = self._scene_eye(scene, _check_pose(pose))
        deadline = time.monotonic() + timeout_s
        while self._layer.current(eye) is None:
            if self._layer.error or time.monotonic() > deadline:
                return False
            time.sleep(0.005)
        return True

    def prefetch_pose(self, pose) -> None:
        """The eye is about to jump to `pose` (a virtual displacement): have the far layer built there meanwhile
        (async; frames go on with the current one). Call in the rendering thread; `ready_for(pose)` says when."""
        if self._layer is not None:
            self._layer.prefetch(self._scene_eye(self._require_scene(), _check_pose(pose)))

    def ready_for(self, pose) -> bool:
        """Whether a frame at `pose` would be drawn with a far layer (or needs none); any thread."""
        layer = self._layer
        return layer is None or layer.ready_at(self._scene_eye(self._require_scene(), _check_pose(pose)))

    def far_layer_status(self) -> dict:
        """Mode, frames drawn with the far layer and in full, layers built, the builder's error ("" if none),
        process id (None unless async), and the latest and largest time from asking for a layer to using it (s)."""
        layer = self._layer
        return {"mode": self.far_layer_mode if layer is not None else "off", "layer_frames": self.layer_frames,
                "full_frames": self.full_frames, "builds": layer.builds if layer is not None else 0,
                "error": (layer.error or "") if layer is not None else "",
                "pid": layer.pid if layer is not None else None,
                "latency_s": layer.latency if layer is not None else 0.0,
                "max_latency_s": layer.max_latency if layer is not None else 0.0}

    def _layer_edit(self, edit: tuple) -> None:
        """An edit of the scene, to the far layer. An edit sent ahead to its builder (a `sky`, `move_object` or
        `remove_object` being prepared) is withdrawn first when this edit is another: the layers built for this
        edit must not show what is not on the dome yet (its swap then sends it again, as any edit)."""
        layer = self._layer
        if layer is None:
            return
        from .far_layer import same_edit

        ahead = layer.ahead
        if ahead is not None and not same_edit(edit, ahead) and (undo := self._undo(ahead)) is not None:
            layer.withdraw(ahead, undo)
        layer.edit(edit)

    def _undo(self, edit: tuple) -> tuple | None:
        """The far-layer edit that restores what `edit`, not made here, changed in the builder; None where the
        renderer draws its far field from a texture (no far field table to restore)."""
        if edit[0] == "far":
            return None if self._table is None else ("far", self._table)
        name = edit[1]
        if edit[0] == "hide":
            return ("show", name)
        current = self.scene.objects.get(name)  # "move": where the object is now (gone: hidden)
        return ("hide", name) if current is None else ("move", name, current)

    def _ensure_far_texture(self) -> None:
        """The far field as a cube texture, for a scene whose frames use the table (a cube-map picture)."""
        if self._far_tex is None:
            self._far_tex = self._make_far_texture(self.scene)

    def _require_scene(self) -> Scene:
        if self.scene is None:
            raise RuntimeError("no scene loaded: call set_scene() first")
        return self.scene

    # ----------------------------------------------------------------------------------------- edits
    def rotate_scene(self, angle: float, pivot=None) -> None:
        """Rotate the whole scene about the vertical by `angle` (rad, absolute, counter-clockwise) through
        `pivot` (x, y) m (default: unchanged). Takes effect on the next frame; nothing is re-uploaded."""
        scene = self._require_scene()
        if not np.isfinite(angle):
            raise ValueError(f"scene rotation must be finite, got {angle!r}")
        if pivot is not None:
            p = np.asarray(pivot, dtype=np.float64)
            if p.shape != (2,) or not np.all(np.isfinite(p)):
                raise ValueError(f"rotation pivot must be (x, y) in metres, got {pivot!r}")
            scene.pivot = (float(p[0]), float(p[1]))
        scene.rotation = float(angle)

    def _moved(self, name: str, position=None, yaw: float | None = None):
        """The named object moved to `position` (3,) m and/or turned to `yaw` (rad)."""
        from .scene import SceneObject

        obj = self._object(name)
        return SceneObject(obj.mesh, obj.position if position is None else position,
                           obj.yaw if yaw is None else yaw, obj.scale)

    def prepare_move(self, name: str, position=None, yaw: float | None = None):
        """`move_object`'s numpy work (the object's vertices and chunk bounds where it goes), for any thread: a
        `PreparedMove` to hand to `move_object`, which then only uploads it. Raises what `move_object` raises."""
        from .prepared import PreparedMove

        scene, meshes = self._require_scene(), self._meshes
        base = self._object(name)
        moved = self._moved(name, position, yaw)
        return PreparedMove(scene, meshes, name, base, moved, meshes.moved(name, moved))

    @_gl_current
    def move_object(self, name: str, position=None, yaw: float | None = None, prepared=None) -> None:
        """Move a named object to `position` (3,) m and/or turn it to `yaw` (rad); `prepared`: `prepare_move`'s
        result for the same arguments, used unless the scene, its meshes or the object changed since."""
        scene = self._require_scene()
        if prepared is not None and prepared.scene is scene and prepared.meshes is self._meshes \
                and prepared.name == name and scene.objects.get(name) is prepared.base:
            moved, data = prepared.moved, prepared.data
        else:
            moved = self._moved(name, position, yaw)
            data = self._meshes.moved(name, moved)
        self._meshes.apply_move(name, data)
        scene.objects[name] = moved
        self._layer_edit(("move", name, moved))

    def prefetch_edit(self, pose, op: str, **kwargs) -> None:
        """A "move_object" or "remove_object" about to come, the eye at `pose`: the async far layer is built with
        it meanwhile, so that the edit shows with its layer from its first frame (`edit_ready`). Rendering thread."""
        if self._layer is None or op not in ("move_object", "remove_object"):
            return
        if op == "move_object":
            edit = ("move", kwargs["name"], self._moved(**kwargs))
        else:
            self._object(kwargs["name"])
            edit = ("hide", kwargs["name"])
        self._layer.edit_ahead(edit, self._scene_eye(self._require_scene(), _check_pose(pose)))

    def edit_ready(self, pose) -> bool:
        """Whether a prefetched edit can be shown with its far layer at `pose` (True when none is); any thread."""
        layer = self._layer
        return layer is None or layer.edit_ready(self._scene_eye(self._require_scene(), _check_pose(pose)))

    @_gl_current
    def remove_object(self, name: str) -> None:
        """Remove a named object from the scene (instantly: its chunks are no longer drawn)."""
        self._object(name)
        self._meshes.hide(name)
        del self.scene.objects[name]
        self._layer_edit(("hide", name))

    @_gl_current
    def add_object(self, name: str, obj) -> None:
        """Add (or replace) a named `SceneObject`; the mesh buffers are rebuilt (previous kept on error)."""
        scene = self._require_scene()
        from .scene import SceneObject

        if not isinstance(name, str) or not name:
            raise ValueError(f"object name must be a non-empty string, got {name!r}")
        if not isinstance(obj, SceneObject):
            raise ValueError(f"object {name!r} must be a SceneObject, got {type(obj).__name__}")
        obj.mesh.validate(name)
        objects = dict(scene.objects)
        objects[name] = obj
        trial = Scene(far=scene.far, objects=objects, name=scene.name)
        meshes = MeshBuffers(self.ctx, self._mesh_prog, trial.objects, self.chunk_size, self.lod_angle,
                             gpu_cull=self._gpu is not None)
        if self._meshes is not None:
            self._meshes.release()
        self._meshes = meshes
        scene.objects = objects
        self._layer_edit(("objects", dict(objects)))

    def scale_channel(self, channel: str, factor: float) -> None:
        """Scale one channel ('green', 'blue' or 'uv'); factor 0 removes it."""
        from .channels import CHANNELS

        scene = self._require_scene()
        if channel not in CHANNELS:
            raise ValueError(f"unknown channel {repr(channel)[:60]}; allowed: {', '.join(CHANNELS)}")
        gains = list(scene.channel_gain)
        gains[CHANNELS.index(channel)] = factor
        scene.channel_gain = check_channel_gain(gains)
        self._convert.configure(channel_gain=scene.channel_gain)

    def swap_green_blue(self, swap: bool = True) -> None:
        if not isinstance(swap, bool):
            raise ValueError(f"swap_green_blue must be true or false, got {swap!r}")
        scene = self._require_scene()
        scene.swap_green_blue = swap
        self._convert.configure(swap_green_blue=scene.swap_green_blue)

    @_gl_current
    def set_lowpass(self, cutoff_deg: float | None) -> None:
        """Angular low-pass: spatial periods shorter than `cutoff_deg` are attenuated below 1/2 (None: off)."""
        scene = self._require_scene()
        check_lowpass(cutoff_deg, self.footprint_deg)
        old = self._fwhm, self._kernel_matrix
        self._set_footprint(cutoff_deg)
        if self._table is not None:
            try:
                self._table = FarFieldTable.of_scene(scene, self._directions, self._fwhm)
            except BaseException:
                self._fwhm, self._kernel_matrix = old
                raise
        scene.lowpass_deg = cutoff_deg
        if self._fwhm != old[0]:
            self._restart_layer()

    def set_contrast(self, contrast: float) -> None:
        """Scale every channel's deviations from its mean over the dome (1: unchanged, 0: uniform)."""
        scene = self._require_scene()
        check_contrast(contrast)
        scene.contrast = float(contrast)
        self._convert.configure(contrast=scene.contrast)

    def set_brightness(self, brightness: float) -> None:
        """Global drive scale in [0, 1] (1: a radiance of 1 drives an LED of gain 1 fully)."""
        self._convert.configure(brightness=brightness)

    @property
    def brightness(self) -> float:
        """The global drive scale in [0, 1] (`set_brightness`; it stays across scene loads)."""
        return self._convert.brightness

    def _object(self, name: str):
        scene = self._require_scene()
        if name not in scene.objects:
            known = ", ".join(sorted(scene.objects)) or "none"
            raise ValueError(f"no object named {repr(name)[:60]} in scene {scene.name!r}; objects: {known}")
        return scene.objects[name]

    # ------------------------------------------------------------------------------------------ frames
    def view_rotation(self, pose: Pose) -> np.ndarray:
        """(3, 3) dome frame -> world frame for this pose and the scene's rotation."""
        return _rot_z(pose.heading - self._require_scene().rotation)

    @_gl_current
    def render(self, pose, out: np.ndarray | None = None, t: float | None = None) -> np.ndarray:
        """The LED frame (20350, 2) uint16 the dome shows for an eye at `pose` at time `t` (s since set_scene).

        `out` is a preallocated (20350, 2) uint16 array to write into (allocated when None).
        """
        scene = self._require_scene()
        pose = _check_pose(pose)
        if out is None:
            out = np.empty((N_PIXELS, 2), dtype=np.uint16)
        elif out.shape != (N_PIXELS, 2) or out.dtype != np.uint16 or not out.flags.c_contiguous:
            raise ValueError(f"out must be a C-contiguous ({N_PIXELS}, 2) uint16 array, got {out.shape} {out.dtype}")
        t = self.clock.now() - self._t0 if t is None else _check_time(t)
        t0 = time.perf_counter()
        q = self.view_rotation(pose)
        self._last_q = q
        pairs = self._pairs
        psi = pose.heading - scene.rotation - scene.yaw_rate * t
        meshes = self._meshes is not None and self._meshes.drawable
        self.last_full_render = False
        gpu = self._gpu is not None
        if self._table is not None and not meshes:
            t1 = time.perf_counter()
            if gpu:
                self._run_gpu(FAR_ONLY, psi=psi)
            else:
                self._table.lookup(psi, pairs)
        else:
            from .kernels import sample_over_far, sample_pairs

            level, texels, indptr, indices, weights = self._sampling()
            over_table = self._table is not None
            layer = None if self._layer is None else self._layer.current(self._scene_eye(scene, pose))
            self.last_full_render = layer is None and meshes
            if self._layer is not None:
                if layer is None:
                    self.full_frames += 1
                else:
                    self.layer_frames += 1
            # the far field: the scene's table is looked up on the GPU path's device; a far layer's (rewritten in
            # place), and every table on the CPU path, by the helper thread while GL draws
            lookup_here = over_table and not (gpu and layer is None)
            if lookup_here:
                helper = self._helper_thread()
                far = self._table if layer is None else layer[0]
                looked_up = helper.submit(far.lookup, psi, self._far_pairs)
            texels = self._render_cube(scene, pose, q, t, level, texels, background=not over_table,
                                       chunks=None if layer is None else layer[1], read_back=not gpu)
            t1 = time.perf_counter()
            if gpu:
                if lookup_here:
                    self._finish(looked_up, far.lookup, psi, self._far_pairs)
                self._run_gpu(OVER_FAR if over_table else ATLAS, level, self._far_pairs if lookup_here else None,
                              psi)
            elif over_table:  # then each thread samples half of the LEDs
                self._finish(looked_up, far.lookup, psi, self._far_pairs)
                n = len(indptr) - 1
                args = (indptr, indices, weights, texels, self._channel, self._far_pairs, pairs)
                half = helper.submit(sample_over_far, *args, 0, n // 2)
                sample_over_far(*args, n // 2, n)
                self._finish(half, sample_over_far, *args, 0, n // 2)
            else:
                sample_pairs(indptr, indices, weights, texels, self._channel, pairs)
                if self._bright:  # a far field above 1 (the float atlas): clipped after the footprint, as its table
                    np.minimum(pairs, np.float32(1.0), out=pairs)
        t2 = time.perf_counter()
        if gpu:
            np.copyto(out, self._gpu.frame)
        else:
            self._convert(pairs, out)
        t3 = time.perf_counter()
        self.last_timings = {"render": t1 - t0, "sample": t2 - t1, "convert": t3 - t2}
        return out

    def _run_gpu(self, mode: int, level: int = 0, far_pairs: np.ndarray | None = None, psi: float = 0.0) -> None:
        """The GPU path's passes for this frame: gains re-uploaded after a change, the footprint matrix after a new
        footprint, the scene's far-field table after a new one (looked up at yaw `psi` unless `far_pairs` are
        given); the frame and its datagrams land in `self._gpu`."""
        conv = self._convert
        if self._gain_version != conv.version:
            self._gpu.set_gain(conv.gain)
            self._gain_version = conv.version
        if mode != FAR_ONLY:
            _, _, indptr, indices, weights = self._sampling()
            self._gpu.set_matrix((self._fwhm, level), indptr, indices, weights)
        if mode != ATLAS and far_pairs is None:
            self._gpu.set_table(self._table)
        self._gpu.run(mode, self._atlas, level, self.face_size >> level, far_pairs, psi, conv.contrast,
                      conv.swap_green_blue, clip=mode == ATLAS and self._bright)

    @property
    def datagrams(self) -> np.ndarray | None:
        """The last frame's 55 VIDEO datagrams, (55, 1112) uint8 with INFO 0 (set the sequence before sending), as
        packed on the GPU path; None on the CPU path (encode with `firmware_proto.video.encode_frame`)."""
        return None if self._gpu is None else self._gpu.datagrams

    @property
    def on_hardware_gpu(self) -> bool:
        """Whether the per-LED path runs on the GL device and that device is not a software driver."""
        return self._gpu is not None and default_path(self.gl_renderer) == "gpu"

    @_gl_current
    def keep_gpu_busy(self, clock, until: float) -> int:
        """GPU path: run the busy pass again and again until `until` (s on `clock`), so that the GPU keeps its
        clocks between frames; stops one (longest recent) pass early and yields the GIL after each, and after one
        pass on a clock that did not move. Returns the passes run; none on the CPU path."""
        if self._gpu is None:
            return 0
        runs = 0
        while clock.now() + self._busy_s < until:
            t0 = clock.now()
            self._gpu.busy()
            runs += 1
            if clock.now() <= t0:  # a simulated clock does not move while the GPU works: nothing to wait for
                break
            self._busy_s = max(0.99 * self._busy_s, clock.now() - t0)
            time.sleep(0)
        return runs

    def _finish(self, future, fn, *args) -> None:
        """Wait for work handed to the helper thread; if it has not even started (the helper held off its CPU or
        the GIL), take it back and do it here instead of waiting (counted in `helper_misses`)."""
        if future.cancel():
            self.helper_misses += 1
            fn(*args)
        else:
            future.result()

    def _helper_thread(self):
        """One worker thread for the per-LED loops that release the GIL (started on first use; its scheduling is
        that of the thread that starts it, the frame loop's, even a real-time one whose children start ordinary)."""
        if self._helper is None:
            from concurrent.futures import ThreadPoolExecutor

            policy = os.sched_getscheduler(0) if hasattr(os, "sched_getscheduler") else 0
            priority = os.sched_getparam(0).sched_priority if hasattr(os, "sched_getparam") else 0
            self._helper = ThreadPoolExecutor(max_workers=1, thread_name_prefix="renderer-helper",
                                              initializer=_set_scheduling, initargs=(policy, priority))
        return self._helper

    @staticmethod
    def _scene_eye(scene: Scene, pose: Pose) -> np.ndarray:
        """(3,) eye position (m) in the coordinates of the scene's objects (undoing the scene's rotation)."""
        c = np.array([*scene.pivot, 0.0])
        return c + _rot_z(-scene.rotation) @ (np.array([pose.x, pose.y, pose.z]) - c)

    def _render_cube(self, scene: Scene, pose: Pose, q: np.ndarray, t: float, level: int = 0,
                     texels: np.ndarray | None = None, background: bool = True, chunks=None,
                     read_back: bool = True) -> np.ndarray | None:
        """Draw the six faces for `pose` and read the atlas (mipmap `level`) back into `texels`; returns the array
        read into: `texels` (uint16), or a float32 one of the same shape (values in the same 16-bit units, rounded,
        beyond 65535 where the far field is brighter than 1) when the far field drawn is (`_use_atlas`).

        background: draw the far field behind the meshes (channel 3 = polarised UV); otherwise leave it
        black and write the meshes' coverage into channel 3, for `kernels.sample_over_far`. chunks: (n_chunks,)
        bool, the mesh chunks to draw (default: all). read_back: False leaves the atlas (and its mipmaps up to
        `level`) on the GL device, for the GPU path.
        """
        if background:
            self._ensure_far_texture()
        eye = self._scene_eye(scene, pose)
        if background and scene.far_time_varying:
            old = self._far_tex
            self._far_tex = self._make_far_texture(scene, t, supersample=1)
            old.release()
        bright = background and self._far_tex.extra > 1.0
        if bright != self._bright:
            self._use_atlas(bright)
        q_far = _rot_z(-scene.yaw_rate * t) @ q
        self._draw(q, q_far, eye, background, chunks)
        if texels is None:
            texels = self._texels
        if bright:
            if len(texels) not in self._float_texels:
                self._float_texels[len(texels)] = np.empty(texels.shape, dtype=np.float32)
            texels = self._float_texels[len(texels)]
        if not read_back:
            if level:
                self._atlas.build_mipmaps(0, level)
            return None
        if level == 0:
            self._fbo.read_into(texels, components=4, dtype="f4" if bright else "nu2")
        else:
            self._atlas.build_mipmaps(0, level)
            self._atlas.read_into(texels, level=level)
        if bright:  # in 16-bit units, rounded as the GPU path's sample pass rounds every texel: floor(v * 65535 + 0.5)
            np.multiply(texels, np.float32(65535.0), out=texels)
            np.add(texels, np.float32(0.5), out=texels)
            np.floor(texels, out=texels)
        return texels

    def _draw(self, q: np.ndarray, q_far: np.ndarray, eye: np.ndarray, background: bool = True, chunks=None) -> None:
        """Meshes first, then the far field only where no mesh was drawn (its fragments fail the depth test
        early, so the background pass costs only the uncovered texels)."""
        ctx, n = self.ctx, self.face_size
        self._fbo.use()
        self._fbo.viewport = (0, 0, n, 6 * n)
        ctx.disable(self._mgl.CULL_FACE)
        ctx.enable(self._mgl.DEPTH_TEST)
        ctx.depth_func = "<"
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        if self._meshes is not None and self._meshes.drawable:
            self._mesh_prog["coverage"].value = 0.0 if background else 1.0
            views = cubemap.face_view_matrices(q, eye)
            self._meshes.draw(self._fbo, views, self._proj, q, eye, n, chunks=chunks)
            self._fbo.viewport = (0, 0, n, 6 * n)
        if not background:
            return
        # background at the far plane: face k's (right, up, forward) in world coordinates
        ctx.depth_func = "<="
        basis = np.einsum("kij,lj->kil", cubemap.FACES, q_far)  # (6, 3 axes, 3 world)
        self._bg_prog["face_to_world"].write(basis[:, [1, 2, 0], :].astype("f4").tobytes())
        self._far_tex.use(0)
        self._bg_vao.render(self._mgl.TRIANGLES, vertices=3)
        ctx.depth_func = "<"

    def polariser_angles(self) -> np.ndarray:
        """(55, 9) float64 polariser angles (rad, [0, pi)) from the sky's e-vectors at the UV pixels for the
        last rendered pose; zeros when the scene has no sky."""
        scene = self._require_scene()
        sky = scene.sky
        if sky is None:
            return np.zeros((N_PANELS, UV_PER_PANEL))
        from .sky import e_vector

        q = self._last_q
        world = self._uv_dirs @ q.T
        e_dome = e_vector(world, sky.sun) @ q
        return polariser_angles(self._uv_dirs, e_dome, self._uv_axes).reshape(N_PANELS, UV_PER_PANEL)

    @_gl_current
    def cube_map(self, pose, t: float | None = None) -> np.ndarray:
        """(6, N, N, 4) float32 linear [G, B, UV, polarised UV] atlas for `pose` (rows bottom-up, faces in
        `cubemap.FACES` order), rendered through GL whatever path `render` takes."""
        scene = self._require_scene()
        pose = _check_pose(pose)
        t = self.clock.now() - self._t0 if t is None else _check_time(t)
        texels = self._render_cube(scene, pose, self.view_rotation(pose), t)
        n = self.face_size
        return (texels.astype(np.float32) / 65535.0).reshape(6, n, n, 4)

    def release(self) -> None:
        """Release the helper thread, the far layer and every GL object with the context; again: nothing. Every GL
        method called after raises RuntimeError."""
        if self._released:
            return
        self._released = True
        if self._helper is not None:
            self._helper.shutdown()
            self._helper = None
        with self.ctx:
            self._release_discarded()
            while self._retired:
                self._retired.popleft().release()
            if self._layer is not None:
                self._layer.release()
                self._layer = None
            for res in (self._far_tex, self._meshes, self._gpu):
                if res is not None:
                    res.release()
        self.ctx.release()


def _set_scheduling(policy: int, priority: int) -> None:
    """The calling thread gets `policy` (as `os.sched_getscheduler` gives it) and `priority`; where that is not
    allowed or not Linux it stays as it started."""
    try:
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except (AttributeError, OSError):
        pass
