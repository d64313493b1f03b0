"""Scenes prepared off the frame loop: everything a scene load needs but its GL uploads, done in another process.

`prepare_scene(renderer, spec, pose)` starts the scene's own process (a fresh interpreter), which parses the
scene (files included), builds its far-field table and its meshes' vertex arrays (`MeshArrays`) and hands them
over in shared memory (`antarium.core.handover`): the server's process only maps them, so no parsing, random
draw, import or large copy ever holds the frame loop's interpreter lock. With an async far layer that process
stays on as the layer's builder (it has the objects already) and `prepare_scene` waits until it has a layer
for the eye at `pose()`; `Renderer.set_scene(prepared)` then only uploads the buffers and swaps everything in
between two frames. A `Scene` object (made in this process already) is prepared in the calling thread.
"""

from __future__ import annotations

import math
import pickle
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from antarium.core.childproc import ChildProcess, connection_from_arg
from antarium.core.handover import Handover, discard, dump, load
from antarium.core.pose import Pose

from .farfield import FarFieldTable
from .meshbuffers import MeshArrays
from .scene import Scene

#: how long `prepare_scene` waits for the far layer's first table (s) before handing the scene over without it
LAYER_WAIT_S = 60.0
#: how long the scene's process may take to hand the scene over (s) before it is taken as hung: killed, the load fails
PREPARE_TIMEOUT_S = 300.0


@dataclass
class PreparedScene:
    """A scene ready for `Renderer.set_scene`: the scene, its far-field table (None: drawn from a cube texture),
    its meshes' arrays (None: no objects), its started async far layer (None: none, or made by the renderer), the
    upload of its arrays and, on the GPU path, of its table, begun in the GL thread (`Renderer.upload_step`; None:
    not begun), and whether it was shown or released (`closed`: nothing more to upload)."""

    scene: Scene
    table: FarFieldTable | None
    arrays: MeshArrays | None
    layer: object | None = None
    upload: object | None = None
    gpu_table: object | None = None
    closed: bool = False
    _lock: threading.Lock = field(default_factory=threading.Lock, init=False, repr=False, compare=False)

    def staged(self, name: str, make: Callable[[], object]) -> object | None:
        """`upload` or `gpu_table` (`name`), made by `make()` (GL thread) when there is none yet; None once the
        scene is released. `release` may run in another thread meanwhile: what `make` made then is discarded here
        (handed to the GL thread), not left behind."""
        with self._lock:
            if self.closed:
                return None
            staged = getattr(self, name)
        if staged is not None:
            return staged
        staged = make()
        with self._lock:
            if not self.closed:
                setattr(self, name, staged)
                return staged
        staged.discard()
        return None

    def release(self) -> None:
        """Free what a prepared scene that will not be shown holds (any thread): its far layer's process, and its
        uploads' buffers (handed to the GL thread)."""
        with self._lock:
            self.closed = True
            self.arrays = None  # nothing more to upload
            staged = [self.upload, self.gpu_table]
            self.upload = self.gpu_table = None
        if self.layer is not None:
            self.layer.release()
            self.layer = None
        for stage in staged:
            if stage is not None:
                stage.discard()


@dataclass(frozen=True)
class PreparedFar:
    """A new far field for a renderer's current scene (`Renderer.prepare_far`, any thread), for `Renderer.set_far`:
    the scene it is for, its far-field layers, and the footprint FWHM (rad) and far-field table it was made with
    (None: the scene is drawn from a cube texture, made at the swap)."""

    scene: Scene
    far: list
    fwhm: float
    table: FarFieldTable | None


@dataclass(frozen=True)
class PreparedMove:
    """An object's move with its numpy work done (`Renderer.prepare_move`, any thread), for `Renderer.move_object`:
    used there only while the scene, its meshes and the named object are still those it was made from (`base`)."""

    scene: Scene
    meshes: object
    name: str
    base: object
    moved: object
    data: tuple


@dataclass(frozen=True)
class SceneSettings:
    """What preparing a scene needs of its renderer, as plain data (it crosses to the scene's process).

    directions (P, 3) float64 LED directions; footprint_deg: LED acceptance FWHM; fast_far_field: far fields
    that allow it come from a `FarFieldTable`; chunk_size (m); far_layer: "off", "sync" or "async", with
    near_radius (m), layer_error (rad), layer_face_size (texels), lod_texels and the async builder's nice value as
    in `Renderer`.
    """

    directions: np.ndarray
    footprint_deg: float
    fast_far_field: bool
    chunk_size: float
    far_layer: str
    near_radius: float
    layer_error: float
    layer_face_size: int
    lod_texels: float
    builder_nice: int

    @classmethod
    def of(cls, renderer) -> SceneSettings:
        return cls(renderer._directions, renderer.footprint_deg, renderer.fast_far_field, renderer.chunk_size,
                   renderer.far_layer_mode, renderer.near_radius, renderer.far_layer_error,
                   renderer.layer_face_size, renderer.lod_texels, renderer.builder_nice)

    def table_ok(self, scene: Scene) -> bool:
        """Whether the far field comes from a `FarFieldTable` (static, or only turning about the vertical)."""
        return self.fast_far_field and not scene.far_time_varying

    def layer_args(self, scene: Scene, table: FarFieldTable | None) -> tuple | None:
        """(near radius, error, face size, chunk size, LOD angle) of the scene's far layer; None when it has none
        (layer off, no table, no objects, or a turning scene)."""
        if self.far_layer == "off" or table is None or not scene.objects or scene.yaw_rate != 0:
            return None
        from . import cubemap

        lod = math.radians(self.lod_texels * cubemap.largest_texel_deg(self.layer_face_size))
        return self.near_radius, self.layer_error, self.layer_face_size, self.chunk_size, lod

    def build(self, scene: Scene) -> PreparedScene:
        """The scene's far-field table and mesh arrays (the CPU work of a load; no GL)."""
        from .renderer import footprint_fwhm

        table = FarFieldTable.of_scene(scene, self.directions, footprint_fwhm(self.footprint_deg, scene.lowpass_deg)) \
            if self.table_ok(scene) else None
        arrays = MeshArrays(scene.objects, self.chunk_size) if scene.objects else None
        return PreparedScene(scene, table, arrays)


def prepare_scene(renderer, spec, pose: Callable[[], Pose] | None = None,
                  timeout_s: float = LAYER_WAIT_S) -> PreparedScene:
    """The CPU half of `renderer.set_scene(spec)` (no GL; any thread). pose: the eye's pose now (called while
    waiting for the far layer; None: do not wait). Raises what `build_scene` raises."""
    from .far_layer import FarLayer

    settings = SceneSettings.of(renderer)
    released = lambda: renderer._released  # noqa: E731 - the server stopped: nothing prepared is shown
    if isinstance(spec, Scene):
        prepared, process = settings.build(spec), None
    else:
        prepared, process = _prepare_in_process(spec, settings, released)
    args = settings.layer_args(prepared.scene, prepared.table) if settings.far_layer == "async" else None
    if process is not None and args is None:
        _stop(process)
    if args is None:
        return prepared
    radius, error, *rest = args
    prepared.layer = FarLayer("async", None, None if process else dict(prepared.scene.objects), prepared.table,
                              radius, error, *rest, prepared.arrays.near_chunks, process=process,
                              nice=settings.builder_nice)
    if pose is not None:
        await_layer(prepared, lambda: renderer._scene_eye(prepared.scene, pose()), timeout_s, fresh=False,
                    cancelled=released)
    return prepared


def await_layer(prepared: PreparedScene, eye: Callable[[], np.ndarray], timeout_s: float = LAYER_WAIT_S,
                fresh: bool = True, cancelled: Callable[[], bool] | None = None) -> None:
    """Wait until the prepared scene's far layer (if any) has a layer usable at `eye()` (scene coordinates, m);
    fresh: one it would not rebuild yet (within the refresh distance) or else one asked for since this call, as
    a scene about to be swapped in should have, so that its first frames do not outwalk it. Returns early when
    the builder has stopped, `cancelled()` (the renderer released: the scene will not be shown) or after
    `timeout_s`: the scene is then shown anyway, its frames drawn in full until a layer is in, as at start-up."""
    layer = prepared.layer
    if layer is None:
        return
    deadline = time.monotonic() + timeout_s
    asked = layer.builds + layer.building  # a layer built after these was asked for during the wait
    while True:
        at = eye()
        usable = layer.current(at) is not None
        if usable and (not fresh or layer.fresh(at) or layer.builds > asked) \
                or layer.error or time.monotonic() > deadline or (cancelled is not None and cancelled()):
            return
        time.sleep(0.005)


def _prepare_in_process(spec, settings: SceneSettings,
                        released: Callable[[], bool]) -> tuple[PreparedScene, ChildProcess]:
    """Build `spec` in the scene's process: (the prepared scene, that process, waiting for "stop" or its layer's
    tables). Raises what `build_scene` raised there; RuntimeError when the process itself failed, did not answer
    within `PREPARE_TIMEOUT_S`, or `released()` (the renderer was released meanwhile: the server stopped)."""
    process = ChildProcess(__name__, connect=True, idle=True)  # preparing never takes a CPU from the frame loop
    deadline = time.monotonic() + PREPARE_TIMEOUT_S
    request = None
    try:
        request = _sender(process, ("prepare", spec, settings))  # the settings alone (0.5 MB) fill the pipe
        while not process.conn.poll(0.05):  # waits without the interpreter lock
            if not process.running and not process.conn.poll():
                raise RuntimeError(f"the scene's process ended (exit code {process.exitcode}) before answering: "
                                   f"{process.output(300).strip() or 'no output'}")
            if released():
                raise RuntimeError("the renderer was released (the server stopped) while the scene was prepared")
            if time.monotonic() > deadline:
                raise RuntimeError(f"the scene's process (pid {process.pid}) did not answer within "
                                   f"{PREPARE_TIMEOUT_S:g} s (hung); stopped")
        kind, payload = process.conn.recv()
        if kind == "error":
            raise payload
        scene, table, arrays = load(payload)
    except BaseException:
        _stop(process, request)
        raise
    return PreparedScene(scene, table, arrays), process


def _send_quietly(conn, data: bytes) -> None:
    """`data` (a pickle) down `conn`; nothing when the process at its other end is gone (the wait notices that)."""
    try:
        conn.send_bytes(data)
    except (OSError, EOFError):
        pass


def _sender(process: ChildProcess, message: tuple) -> threading.Thread:
    """A started thread sending `message` to the scene's process: one that never reads (hung) fills the pipe, which
    must not hold the caller."""
    thread = threading.Thread(target=_send_quietly, args=(process.conn, pickle.dumps(message)),
                              name="scene-process-send", daemon=True)
    thread.start()
    return thread


def _stop(process: ChildProcess, request: threading.Thread | None = None) -> None:
    """Ask the scene's process to end, kill it after 5 s, then close the connection. request: the thread still
    sending it the scene asked for, if any: "stop" follows only that whole message (a process that never reads
    it is killed), and the connection is closed only once the thread has returned (it does once the process is
    gone)."""
    if request is not None:
        request.join(1.0)
    senders = [request] if request is not None and request.is_alive() else [_sender(process, ("stop",))]
    if not process.wait(5.0):
        process.proc.kill()
        process.proc.wait()
    for thread in senders:
        thread.join()
    process.close()


def _serve(conn_arg: str) -> None:  # pragma: no cover - runs in the scene's process
    """The scene's process: prepare the scene asked for, hand it over, then stop or build its far layers (at the
    builder's priority: `serve_layers` leaves SCHED_IDLE, which an unprivileged process may do)."""
    import pickle

    from .far_layer import serve_layers
    from .library import build_scene

    conn = connection_from_arg(conn_arg)
    handover: Handover | None = None
    try:
        _, spec, settings = conn.recv()
        try:
            prepared = settings.build(build_scene(spec))
            handover = dump((prepared.scene, prepared.table, prepared.arrays))
        except Exception as exc:  # the load's error, raised again in the server's process
            try:
                conn.send(("error", pickle.loads(pickle.dumps(exc))))
            except Exception:
                conn.send(("error", RuntimeError(f"{type(exc).__name__}: {exc}")))
            return
        # from here this process reads the very pages it handed over: one copy of the scene in memory
        scene, table, _ = load(handover, unlink=False)
        del prepared
        conn.send(("prepared", handover))
        msg = conn.recv()
        if msg[0] == "stop":
            return
        shm_names, nice = msg
        radius, _, face_size, chunk_size, lod = settings.layer_args(scene, table)
        serve_layers(conn, shm_names, nice, table, dict(scene.objects), radius, face_size, chunk_size, lod)
    except (EOFError, KeyboardInterrupt):
        pass
    finally:
        if handover is not None:
            discard(handover)


if __name__ == "__main__":  # pragma: no cover - the scene's process
    import sys

    _serve(sys.argv[1])
