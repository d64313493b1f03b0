"""The far layer: meshes beyond a near radius, rendered from a recent eye position into a footprint-integrated
table, so that each frame draws only the meshes near the eye.

Seen from an eye that moved by |delta| since the layer was rendered, content at distance D >= R (the near
radius) is displaced by at most |delta| / (R - |delta|) radians. The layer is used while that bound stays under
`error` (default 0.5°, a third of the LED pitch: about 17 mm of walking at R = 2 m); otherwise, and until a
layer for the current scene edits exists, the frame is rendered in full. A frame using the layer:

1. draws (at the near face size) the chunks that lie within R of the layer's eye, with their coverage;
2. looks up the layer (a `FarFieldTable`: far meshes over the far field), one bilinear lookup per LED;
3. samples the near atlas over that (`kernels.sample_over_far`).

Near and far chunks are split by their distance from the layer's eye, so every chunk is drawn exactly once.
The layer itself (`FarLayerBuilder`) renders the far chunks world-aligned at `layer_face_size` with their
coverage, resamples the cube bilinearly onto the table grid (`farfield.TableGrid`), blurs it by the LED
footprint and composites it over the scene's far-field table: layer + (1 - layer coverage) x far field, the
same rule by which the near meshes are laid over it per LED.

Two ways to build it, same code: `"sync"` builds in the calling thread whenever the layer is unusable
(deterministic: what a frame shows depends only on the poses; for simulated clocks), `"async"` builds in a
child process with its own GL context (on the other core), continuously while the eye moves, and hands the
tables over in shared memory (`TABLE_SLOTS` of them); frames never wait for it.
"""

from __future__ import annotations

import math
import os
import queue
import threading
import time
import weakref

import numpy as np

from antarium.core.childproc import ChildProcess, connection_from_arg

from . import cubemap, shaders
from .farfield import FarFieldTable, TableGrid
from .meshbuffers import MeshBuffers

MODES = ("off", "sync", "async")
#: the eye may move this fraction of the allowed displacement before an async rebuild is asked for
REFRESH_FRACTION = 0.25
#: weight of the newest frame in the eye's velocity estimate (an exponential average over ~20 frames)
VELOCITY_SMOOTHING = 0.05
#: async: shared tables: the layer in use, one held for a coming displacement or edit, and the one being built
#: (so that a held layer, which the eye may never reach, never stops the frames' own from being renewed)
TABLE_SLOTS = 3
#: async: a builder that has not answered a build this long (s) is taken as hung: it is killed and reported (`error`),
#: and frames are drawn in full, as when it dies (a build takes ~0.1 s; a new scene's first, with its uploads, a few s)
BUILD_TIMEOUT_S = 60.0


def builder_nice() -> int:
    """Nice value for an async layer builder beside the frame loop, which is the calling thread: below a real-time
    loop, 10 (it still has most of the idle time of the loop's other CPU, but yields it at once to the server's
    ordinary threads, which may hold the loop's GIL); beside an ordinary loop, 5 (a quarter of a core against it,
    enough for a layer every ~0.3 s; 10 starved it)."""
    realtime = hasattr(os, "sched_getscheduler") and \
        os.sched_getscheduler(0) & ~os.SCHED_RESET_ON_FORK in (os.SCHED_FIFO, os.SCHED_RR)
    return 10 if realtime else 5


def allowed_displacement(radius: float, error: float) -> float:
    """Largest eye displacement (m) for which content beyond `radius` (m) moves by at most `error` (rad)."""
    return radius * math.tan(error) / (1.0 + math.tan(error))


def cube_taps(directions: np.ndarray, face_size: int) -> tuple[np.ndarray, np.ndarray]:
    """Bilinear taps of (P, 3) world directions in a world-aligned atlas (`cubemap` order): (P, 4) int32 texel
    indices and (P, 4) float32 weights (clamped at face edges)."""
    n = face_size
    d = np.asarray(directions, dtype=np.float64)
    forward = d @ cubemap.FACES[:, 0].T  # (P, 6)
    face = np.argmax(forward, axis=1)
    basis = cubemap.FACES[face]  # (P, 3, 3)
    f = np.einsum("pj,pj->p", d, basis[:, 0])
    a = np.einsum("pj,pj->p", d, basis[:, 1]) / f
    b = np.einsum("pj,pj->p", d, basis[:, 2]) / f
    x = np.clip((a + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    y = np.clip((b + 1.0) * 0.5 * n - 0.5, 0.0, n - 1.0)
    x0 = np.minimum(np.floor(x).astype(np.int64), n - 2)
    y0 = np.minimum(np.floor(y).astype(np.int64), n - 2)
    fx, fy = x - x0, y - y0
    base = face * n * n + y0 * n + x0
    taps = np.stack([base, base + 1, base + n, base + n + 1], axis=1).astype(np.int32)
    weights = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1).astype(np.float32)
    return taps, weights


class FarLayerBuilder:
    """Renders the far layer of a set of objects over a far field, in table form, with the GL context given.

    objects: {name: SceneObject}; far_field: the scene's `FarFieldTable` (its grid is the layer's); radius:
    near radius (m); face_size: world-aligned cube face (texels); chunk_size (m) and lod_angle (rad) as in
    `MeshBuffers`.
    """

    def __init__(self, ctx, objects: dict, far_field: FarFieldTable, radius: float, face_size: int,
                 chunk_size: float, lod_angle: float, near: float = 1e-3, far: float = 1e3):
        import moderngl

        self.ctx, self.far_field, self.radius, self.face_size = ctx, far_field, float(radius), int(face_size)
        self.chunk_size, self.lod_angle = float(chunk_size), float(lod_angle)
        n, g = self.face_size, far_field.grid
        self._mgl = moderngl
        self._prog = ctx.program(vertex_shader=shaders.MESH_VS, fragment_shader=shaders.MESH_FS)
        self._prog["textures"].value = 1
        self._atlas = ctx.texture((n, 6 * n), 4, dtype="nu2")
        self._depth = ctx.depth_renderbuffer((n, 6 * n))
        self._fbo = ctx.framebuffer([self._atlas], self._depth)
        self._proj = cubemap.projection_matrix(near, far)
        self._texels = np.empty((6 * n * n, 4), dtype=np.uint16)
        self._taps, self._weights = cube_taps(g.directions(), n)
        self._field = np.empty((g.n_rows * g.n_cols, 4), dtype=np.float32)
        self.set_far_field(far_field)
        self.meshes: MeshBuffers | None = None
        self.set_objects(objects)

    def set_far_field(self, far_field: FarFieldTable) -> None:
        """The far field under the objects (a new sky): a table on this builder's grid."""
        g = self.far_field.grid
        if far_field.grid.shape != g.shape:
            raise ValueError(f"far field on a {far_field.grid.shape} grid, the layer's is {g.shape}")
        self.far_field, cols = far_field, g.n_cols  # as radiance [G, B, UV, polarised UV], converted once a field
        self._static = np.concatenate([far_field.table_gb[:, :cols], far_field.table_uv[:, :cols]],
                                      axis=2).astype(np.float32) / np.float32(65535.0)

    def set_objects(self, objects: dict) -> None:
        meshes = MeshBuffers(self.ctx, self._prog, objects, self.chunk_size, self.lod_angle)
        if self.meshes is not None:
            self.meshes.release()
        self.meshes = meshes

    def apply(self, edit: tuple) -> None:
        """A scene edit: ("objects", {name: SceneObject}), ("move", name, SceneObject), ("hide", name),
        ("show", name) (a hide undone) or ("far", FarFieldTable)."""
        kind = edit[0]
        if kind == "objects":
            self.set_objects(edit[1])
        elif kind == "far":
            self.set_far_field(edit[1])
        elif kind == "move":
            self.meshes.update_object(edit[1], edit[2])
        elif kind == "hide":
            self.meshes.hide(edit[1])
        elif kind == "show":
            self.meshes.show(edit[1])
        else:
            raise ValueError(f"unknown far-layer edit {kind!r}; allowed: objects, move, hide, show, far")

    def build(self, eye: np.ndarray, out: FarFieldTable) -> FarFieldTable:
        """The far layer seen from `eye` (3,) m, written into the tables of `out` (same grid); returns `out`."""
        from .kernels import gather_bilinear

        ctx, n, g = self.ctx, self.face_size, self.far_field.grid
        eye = np.asarray(eye, dtype=np.float64)
        self._fbo.use()
        self._fbo.viewport = (0, 0, n, 6 * n)
        ctx.enable(self._mgl.DEPTH_TEST)
        ctx.depth_func = "<"
        self._fbo.clear(0.0, 0.0, 0.0, 0.0, depth=1.0)
        meshes = self.meshes
        if meshes is not None and meshes.drawable:
            self._prog["coverage"].value = 1.0
            q = np.eye(3)
            far = ~meshes.near_chunks(eye, self.radius)
            meshes.draw(self._fbo, cubemap.face_view_matrices(q, eye), self._proj, q, eye, n, chunks=far)
        self._fbo.read_into(self._texels, components=4, dtype="nu2")
        gather_bilinear(self._texels, self._taps, self._weights, self._field)
        layer = g.blur(self._field.reshape(g.n_rows, g.n_cols, 4))  # [G, B, UV, coverage]
        uncovered = 1.0 - np.clip(layer[..., 3:4], 0.0, 1.0)
        layer[..., 3] = 0.0  # meshes carry no polarisation
        layer += uncovered * self._static
        g.quantise(layer[..., 0:2], out.table_gb)
        g.quantise(layer[..., 2:4], out.table_uv)
        return out

    def release(self) -> None:
        for res in (self.meshes, self._fbo, self._atlas, self._depth, self._prog):
            if res is not None:
                res.release()
        self.meshes = None


class FarLayer:
    """The current far layer of a renderer, kept up to date by a builder ("sync" or "async").

    process: async only, the `ChildProcess` of a scene prepared in it (`renderers.prepared`), which has the
    objects and far field already and becomes the builder (objects is then None); None: a new one is started.
    nice: the async builder's (default: `builder_nice()` of the calling thread).
    Call `edit` for every change of the scene's objects, then `current(eye)` each frame: it returns
    (layer table, near chunk mask) when a layer for the current objects is within the error bound of `eye`,
    else None (render the frame in full). near_chunks(eye, radius) gives the renderer's own chunk mask.
    """

    def __init__(self, mode: str, ctx, objects: dict | None, far_field: FarFieldTable, radius: float,
                 error: float, face_size: int, chunk_size: float, lod_angle: float, near_chunks, process=None,
                 nice: int | None = None):
        if mode not in ("sync", "async"):
            raise ValueError(f"far layer mode must be one of {', '.join(MODES)}, got {mode!r}")
        self.mode, self.radius = mode, float(radius)
        self.max_shift = allowed_displacement(self.radius, error)
        self._near_chunks = near_chunks
        self.grid = g = far_field.grid
        self.generation = 0
        self._eye = None  # eye, generation and near chunk mask of the layer in use
        self._near = None
        self._gen_ready = -1
        self._index = 0
        self.builds = 0
        #: seconds from asking for a layer to using it: the latest and the largest
        self.latency = self.max_latency = 0.0
        self._asked = 0.0
        self._velocity = EyeVelocity(self.max_shift)
        #: async: a layer asked for ahead of a jump of the eye (`prefetch`): its eye, then (eye, generation, index)
        #: once built; held in a table of its own until a frame's eye is within its range
        self._ahead_eye = None
        self._ahead = None
        #: async: an edit asked for ahead of the renderer's (`edit_ahead`), until the renderer makes it; whether the
        #: builder has it yet (it gets it with the layer built for it); whether the frames' own layer was renewed
        #: while a layer asked for ahead waited
        self._ahead_edit = None
        self._edit_sent = False
        self._renewed = False
        args = (objects, radius, face_size, chunk_size, lod_angle)
        if mode == "sync":
            self._builder = FarLayerBuilder(ctx, objects, far_field, *args[1:])
            self._tables = [FarFieldTable(g, *_empty_tables(g))]
        else:
            self._worker = _Worker(far_field, args, builder_nice() if nice is None else nice, process)
            self._tables = [FarFieldTable(g, gb, uv) for gb, uv in self._worker.tables]

    @property
    def error(self) -> str | None:
        """Why the async builder stopped (frames are then drawn in full), or None."""
        return None if self.mode == "sync" else self._worker.error

    @property
    def pid(self) -> int | None:
        """Process id of the async builder (None when sync)."""
        return None if self.mode == "sync" else self._worker.pid

    @property
    def building(self) -> bool:
        """Whether the async builder is building a layer now (False when sync)."""
        return self.mode == "async" and self._worker.busy

    def edit(self, edit: tuple) -> None:
        """Apply a scene edit (see `FarLayerBuilder.apply`); the layer is unusable until rebuilt, unless the
        edit was sent ahead (`edit_ahead`): its layer is then used from the next frame."""
        if self._ahead_edit is not None and same_edit(edit, self._ahead_edit) and self._edit_sent:
            self._ahead_edit = None
            self.generation += 1
            return
        if self._ahead_edit is not None and not self._edit_sent:  # its layer not begun: renewed as any other
            self._ahead_eye = None
        self._ahead_edit = None
        self.generation += 1
        if self.mode == "sync":
            self._builder.apply(edit)
        else:
            self._worker.send(("edit", edit))

    def _usable(self, eye: np.ndarray) -> bool:
        return self._in_range((self._eye, self._gen_ready), eye)

    def _in_range(self, layer: tuple, eye: np.ndarray, reach: float = 1.0) -> bool:
        """Whether a layer (its eye, generation) is for the current edits and within `reach` of the allowed shift
        of `eye`."""
        return (layer[0] is not None and layer[1] == self.generation
                and float(np.linalg.norm(eye - layer[0])) <= reach * self.max_shift)

    def current(self, eye: np.ndarray):
        """(FarFieldTable, near chunk mask) to draw the frame for `eye` (scene coordinates, m), or None."""
        eye = np.asarray(eye, dtype=np.float64)
        if self.mode == "sync":
            if not self._usable(eye):
                self._asked = time.perf_counter()
                self._builder.build(eye, self._tables[0])
                self._adopt(eye, self.generation, 0)
        else:
            now = time.perf_counter()
            self._velocity.update(eye, now)
            for eye_built, gen, index in self._worker.results():
                if self._ahead_eye is not None and np.array_equal(eye_built, self._ahead_eye):
                    self._ahead, self._ahead_eye = (eye_built, gen, index), None
                elif not self._usable(eye) or self._in_range((eye_built, gen), eye):  # never a usable one for
                    self._adopt(eye_built, gen, index)                               # one the eye has left
            ahead = self._ahead
            if ahead is not None and self._in_range(ahead, eye):
                self._ahead = None
                self._adopt(*ahead)
            elif ahead is not None and ahead[1] < self.generation:
                self._ahead = None
            self._dispatch(eye, now)
        if not self._usable(eye):
            return None
        return self._tables[self._index], self._near

    def fresh(self, eye: np.ndarray) -> bool:
        """Whether the layer in use is for the current edits and within the refresh distance of `eye` (m): an async
        layer asks for no new one yet."""
        return self._in_range((self._eye, self._gen_ready), eye, REFRESH_FRACTION)

    def _dispatch(self, eye: np.ndarray, now: float) -> None:
        """Async: the idle builder's next layer. The frames' own comes first when it is due (the eye moved a
        `REFRESH_FRACTION` of its range, or an edit), once per layer asked for ahead, so that a builder that cannot
        keep up still gets to that; then the layer asked for ahead (`prefetch`, `edit_ahead`), whose edit reaches
        the builder only with it, so that a renewal before it is built without the edit."""
        if self._worker.busy or self.error:
            return
        waiting = self._ahead_eye is not None
        edited = self._ahead_edit is not None and self._edit_sent  # the builder has an edit the frames do not yet
        if not self.fresh(eye) and not edited and not (waiting and self._renewed):
            self._renewed, target = waiting, self._led(eye)
        elif waiting:
            if self._ahead_edit is not None and not self._edit_sent:
                self._ahead_eye = self._led(eye)
                self._worker.send(("edit", self._ahead_edit))
                self._edit_sent = True
            self._renewed, target = False, self._ahead_eye
        else:
            return
        self._asked = now
        self._send_build(target)

    def _led(self, eye: np.ndarray) -> np.ndarray:
        """Where the eye (m) will be when a layer asked for now is in: ahead by the last build's latency (at most
        half the allowed shift), so that a walking ant stays near the middle of the layer's range."""
        return eye + self._velocity.lead(self.latency, 0.5 * self.max_shift)

    def _send_build(self, eye: np.ndarray) -> None:
        """Build a layer for `eye` (m) into a table neither in use nor held."""
        generation = self.generation + (self._ahead_edit is not None and self._edit_sent)
        taken = {self._index if self._eye is not None else None, None if self._ahead is None else self._ahead[2]}
        index = next(k for k in range(len(self._tables)) if k not in taken)
        self._worker.send(("build", eye, generation, index))

    def edit_ahead(self, edit: tuple, eye: np.ndarray) -> bool:
        """Async: have the layer with `edit` built into a spare table, for where the eye (at `eye` now, m) will
        be when it is in (placed when its build begins), while frames go on with the current layer (see
        `_dispatch`); the renderer's own `edit(edit)` then switches to it. False (nothing done) when sync, or
        another edit is ahead already."""
        if self.mode != "async" or self._ahead_edit is not None or self.error:
            return False
        self._ahead_edit, self._edit_sent = edit, False
        self._ahead, self._ahead_eye = None, np.asarray(eye, dtype=np.float64)  # placed when its build begins
        return True

    def edit_ready(self, eye: np.ndarray) -> bool:
        """Whether the layer of an edit sent ahead is built, usable at `eye` (m); True when none is ahead."""
        ahead = self._ahead
        if self._ahead_edit is None or self.error:
            return True
        return ahead is not None and ahead[1] == self.generation + 1 \
            and float(np.linalg.norm(np.asarray(eye, dtype=np.float64) - ahead[0])) <= self.max_shift

    @property
    def ahead(self) -> tuple | None:
        """The edit sent ahead (`edit_ahead`) and not yet made, or None."""
        return self._ahead_edit

    def withdraw(self, edit: tuple, undo: tuple) -> None:
        """Async: the edit sent ahead (`edit_ahead`) will not be made after all: the builder gets `undo`, the edit
        that restores what `edit` changed, if it had `edit` already. Nothing when `edit` does not do what the one
        ahead does (`same_edit`)."""
        if self._ahead_edit is None or not same_edit(edit, self._ahead_edit):
            return
        sent = self._edit_sent
        self._ahead_edit = self._ahead = self._ahead_eye = None
        if sent:
            self.generation += 1  # no layer built with the edit is ever used: those are one generation on
            self.edit(undo)

    def prefetch(self, eye: np.ndarray) -> None:
        """Async: build a layer for `eye` (m), where the eye is about to jump, into a spare table, while frames
        go on with the current one (see `_dispatch`); the first frame whose eye is in its range uses it
        (`ready_at`)."""
        if self.mode != "async" or self.ready_at(eye):
            return
        self._ahead, self._ahead_eye = None, np.array(eye, dtype=np.float64)

    def ready_at(self, eye: np.ndarray) -> bool:
        """Whether a frame at `eye` (m) would find a layer (the current one, or one prefetched); any thread."""
        eye = np.asarray(eye, dtype=np.float64)
        if self.error:
            return True  # nothing to wait for: every frame is drawn in full
        held = (self._ahead, (self._eye, self._gen_ready))
        return any(layer is not None and self._in_range(layer, eye) for layer in held)

    def _adopt(self, eye: np.ndarray, generation: int, index: int) -> None:
        self._eye, self._gen_ready, self._index = np.asarray(eye, dtype=np.float64), generation, index
        self._near = self._near_chunks(self._eye, self.radius)
        self.builds += 1
        self.latency = time.perf_counter() - self._asked
        self.max_latency = max(self.max_latency, self.latency)

    def release(self) -> None:
        if self.mode == "sync":
            self._builder.release()
        else:
            self._worker.close()


class EyeVelocity:
    """The eye's velocity (m/s), an exponential average over ~20 frames (`VELOCITY_SMOOTHING`). A step longer than
    `max_step` (m) from one frame to the next is a jump (a displacement, a new origin), not walking: it is left out,
    so that the layers built after a displacement are not led off along it."""

    def __init__(self, max_step: float) -> None:
        self.max_step = float(max_step)
        self.value = np.zeros(3)
        self._last: tuple[np.ndarray, float] | None = None

    def update(self, eye: np.ndarray, now: float) -> None:
        """A frame's eye (3,) float64 (m) at time `now` (s)."""
        last, self._last = self._last, (eye, now)
        if last is None or now <= last[1]:
            return
        step = eye - last[0]
        if float(np.linalg.norm(step)) <= self.max_step:
            self.value += VELOCITY_SMOOTHING * (step / (now - last[1]) - self.value)

    def lead(self, seconds: float, limit: float) -> np.ndarray:
        """Where the eye will be in `seconds` relative to now (3,) (m), at most `limit` (m) away."""
        lead = self.value * seconds
        norm = float(np.linalg.norm(lead))
        return lead * (limit / norm) if norm > limit else lead


def same_edit(a: tuple, b: tuple) -> bool:
    """Whether two far-layer edits do the same (a move to the same place, hiding the same object, or the same new
    far field)."""
    if a[0] == b[0] == "far":
        return a[1] is b[1]
    if a[0] != b[0] or a[1] != b[1] or a[0] not in ("move", "hide"):
        return False
    return a[0] == "hide" or (np.array_equal(a[2].position, b[2].position) and a[2].yaw == b[2].yaw
                              and a[2].mesh is b[2].mesh and a[2].scale == b[2].scale)


def _empty_tables(grid: TableGrid, buffer=None) -> tuple[np.ndarray, np.ndarray]:
    """([G, B], [UV, polarised UV]) (rows, cols + 1, 2) uint16 tables: zeroed, or views of `buffer` (both
    tables back to back)."""
    shape = (*grid.shape, 2)
    if buffer is None:
        return np.zeros(shape, np.uint16), np.zeros(shape, np.uint16)
    size = int(np.prod(shape)) * 2
    return tuple(np.ndarray(shape, dtype=np.uint16, buffer=buffer, offset=k * size) for k in range(2))


class _Worker:
    """The async builder: a child interpreter with its own GL context, `TABLE_SLOTS` tables in shared memory. A new
    child gets the objects and far field pickled; a scene's own process (`process`) has them already. Messages go
    out in order through a thread of their own: a new far field (7 MB for the habitat) takes 10-20 ms to pass the
    pipe, which the frame that sends it must not wait for."""

    def __init__(self, far_field: FarFieldTable, args: tuple, nice: int, process=None):
        from multiprocessing import shared_memory

        g = far_field.grid
        nbytes = int(np.prod(g.shape)) * 2 * 2 * 2  # two uint16 tables of two channels
        self._shm = [shared_memory.SharedMemory(create=True, size=nbytes) for _ in range(TABLE_SLOTS)]
        self.tables = [_empty_tables(g, s.buf) for s in self._shm]
        for gb, uv in self.tables:
            gb[...] = 0
            uv[...] = 0
        self._child = ChildProcess(__name__, connect=True) if process is None else process
        self._conn = self._child.conn
        names = [s.name for s in self._shm]
        self.busy = False
        self._asked = 0.0  # when the build in progress was sent (time.monotonic(), s)
        self.error: str | None = None
        self._outbox: queue.SimpleQueue = queue.SimpleQueue()
        self._failed: list[str] = []  # the sending thread's error
        # the thread holds the queue and the connection, not the worker: a worker dropped without `close` still
        # ends it (and, with the connection, its child process)
        self._sender = threading.Thread(target=_send_all, args=(self._outbox, self._conn, self._failed),
                                        name="far-layer-send", daemon=True)
        self._sender.start()
        weakref.finalize(self, self._outbox.put, None)
        self._outbox.put((names, nice) if process is not None else
                         (names, nice, far_field.table_gb, far_field.table_uv, g, args))

    @property
    def pid(self) -> int:
        return self._child.pid

    def _sender_failed(self) -> None:
        """The sending thread's error, once, as the worker's."""
        if self._failed and self.error is None:
            self.error = self._failed[0]

    def send(self, message: tuple) -> None:
        self._sender_failed()
        if self.error is not None:
            return
        self._outbox.put(message)
        if message[0] == "build":
            self.busy, self._asked = True, time.monotonic()

    def results(self):
        """Layers finished since the last call: (eye, generation, table index) each."""
        out = []
        self._sender_failed()
        try:
            while self.error is None and self._conn.poll():
                msg = self._conn.recv()
                if msg[0] == "built":
                    self.busy = False
                    out.append(msg[1:])
                elif msg[0] == "error":
                    self.error, self.busy = msg[1], False
        except (OSError, EOFError) as exc:
            self.error = f"far-layer process gone: {exc}"
        if self.busy and self.error is None and time.monotonic() - self._asked > BUILD_TIMEOUT_S:
            self.error, self.busy = f"far-layer process {self.pid} hung: no layer built in {BUILD_TIMEOUT_S:g} s; " \
                "killed", False
            self._child.kill()
        return out

    def close(self) -> None:
        self._outbox.put(("stop",))
        self._outbox.put(None)
        self._sender.join(5)
        if not self._child.wait(5):
            self._child.kill()
        self._child.close()
        self.tables = []
        for s in self._shm:
            s.close()
            s.unlink()


def _send_all(outbox: queue.SimpleQueue, conn, failed: list[str]) -> None:
    """A `_Worker`'s sending thread: each message in the order given, until None (or the first failure, in
    `failed`)."""
    while (message := outbox.get()) is not None:
        try:
            conn.send(message)
        except (OSError, EOFError) as exc:
            failed.append(f"far-layer process gone: {exc}")
            return


def _serve(conn_arg: str) -> None:  # pragma: no cover - runs in the child process
    """Child process: receive the objects and far field, then build layers on request."""
    conn = connection_from_arg(conn_arg)
    shm_names, nice, static_gb, static_uv, grid, args = conn.recv()
    serve_layers(conn, shm_names, nice, FarFieldTable(grid, static_gb, static_uv), *args)


def serve_layers(conn, shm_names: list[str], nice: int, far_field: FarFieldTable, objects: dict, radius: float,
                 face_size: int, chunk_size: float, lod_angle: float) -> None:  # pragma: no cover - child process
    """In the builder's process: build layers on request into the shared tables `shm_names` until told to stop
    (or the connection ends); errors are reported to the renderer, which then renders every frame in full."""
    import os
    from multiprocessing import resource_tracker, shared_memory

    from .gl import create_context

    try:  # the frame loop comes first: ordinary scheduling even if the loop's thread is real-time
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        os.nice(nice)
    except (AttributeError, OSError):
        pass
    shms = [shared_memory.SharedMemory(name=name) for name in shm_names]
    for s in shms:  # the renderer owns the tables: this interpreter's resource tracker must not unlink them
        resource_tracker.unregister(s._name, "shared_memory")
    tables = [FarFieldTable(far_field.grid, *_empty_tables(far_field.grid, s.buf)) for s in shms]
    try:
        builder = FarLayerBuilder(create_context(), objects, far_field, radius, face_size, chunk_size, lod_angle)
        while True:
            msg = conn.recv()
            if msg[0] == "stop":
                break
            if msg[0] == "edit":
                builder.apply(msg[1])
            elif msg[0] == "build":
                _, eye, generation, index = msg
                builder.build(eye, tables[index])
                conn.send(("built", eye, generation, index))
    except (EOFError, KeyboardInterrupt):
        pass
    except Exception as exc:  # reported to the renderer, which then renders every frame in full
        try:
            conn.send(("error", f"{type(exc).__name__}: {exc}"))
        except OSError:
            pass
    finally:
        del tables
        for s in shms:
            s.close()


if __name__ == "__main__":  # pragma: no cover - the async builder's process
    import sys

    _serve(sys.argv[1])
