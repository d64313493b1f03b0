"""Scenes prepared off the frame loop: everything a scene load needs but its GL uploads, done in any thread.

`prepare_scene(renderer, spec, pose)` parses the scene (files included), builds its far-field table and its
meshes' vertex arrays (`MeshArrays`) and, with an async far layer, starts the layer's process and waits until
it has a layer for the eye at `pose()`; `Renderer.set_scene(prepared)` then only uploads the buffers and swaps
everything in between two frames, so that the frame loop is never held by a load.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from antarium.core.pose import Pose

from .farfield import FarFieldTable
from .meshbuffers import MeshArrays
from .scene import Scene

#: how long `prepare_scene` waits for the far layer's first table (s) before handing the scene over without it
LAYER_WAIT_S = 60.0


@dataclass
class PreparedScene:
    """A scene ready for `Renderer.set_scene`: the scene, its far-field table (None: drawn from a cube texture),
    its meshes' arrays (None: no objects) and its started async far layer (None: none, or made by the renderer)."""

    scene: Scene
    table: FarFieldTable | None
    arrays: MeshArrays | None
    layer: object | None = None

    def release(self) -> None:
        """Stop the far layer's process of a prepared scene that will not be shown."""
        if self.layer is not None:
            self.layer.release()
            self.layer = None


def prepare_scene(renderer, spec, pose: Callable[[], Pose] | None = None,
                  timeout_s: float = LAYER_WAIT_S) -> PreparedScene:
    """The CPU half of `renderer.set_scene(spec)` (no GL; any thread). pose: the eye's pose now (called while
    waiting for the far layer; None: do not wait). Raises what `build_scene` raises."""
    from .far_layer import FarLayer
    from .library import build_scene

    scene = spec if isinstance(spec, Scene) else build_scene(spec)
    fwhm = renderer.footprint_fwhm_for(scene.lowpass_deg)
    table = FarFieldTable.of_scene(scene, renderer._directions, fwhm) if renderer._table_ok(scene) else None
    arrays = MeshArrays(scene.objects, renderer.chunk_size) if scene.objects else None
    prepared = PreparedScene(scene, table, arrays)
    if renderer.far_layer_mode != "async" or table is None or not scene.objects or scene.yaw_rate != 0:
        return prepared
    from . import cubemap

    lod = math.radians(renderer.lod_texels * cubemap.largest_texel_deg(renderer.layer_face_size))
    prepared.layer = FarLayer("async", None, dict(scene.objects), table, renderer.near_radius,
                              renderer.far_layer_error, renderer.layer_face_size, renderer.chunk_size, lod,
                              arrays.near_chunks)
    if pose is not None:
        deadline = time.monotonic() + timeout_s
        while prepared.layer.current(renderer._scene_eye(scene, pose())) is None:
            if prepared.layer.error or time.monotonic() > deadline:
                break  # shown anyway: its frames are drawn in full until a layer is in, as at start-up
            time.sleep(0.005)
    return prepared
