"""The far layer (meshes beyond the near radius from a recent eye position) against full renders (real EGL)."""

from __future__ import annotations

import math
import os
import signal
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from conftest import wait_for

from antarium.core.pose import Pose
from antarium.renderers import cubemap
from antarium.renderers.far_layer import EyeVelocity, allowed_displacement, cube_taps
from antarium.renderers.habitat import habitat_scene
from antarium.renderers.kernels import gather_bilinear
from antarium.renderers.renderer import Renderer
from antarium.renderers.scene import SceneObject

#: a walk of 10 cm with turns, eye 1 cm above the ground (as an ant on the ball)
WALK = [Pose(0.002 * k, 0.001 * k, 0.01, 0.02 * k) for k in range(50)]
CHECK = (0, 20, 49)


def small_habitat():
    return habitat_scene(n_tussocks=300, n_stones=60, n_bushes=8, n_trees=4)


def drive_to_radiance(frame: np.ndarray) -> np.ndarray:
    return frame.astype(np.float64) / 65535.0


@pytest.fixture(scope="module")
def reference(dome):
    """Full renders at the default face size (no far layer) at the CHECK poses."""
    r = Renderer(dome)
    r.set_scene(small_habitat())
    frames = [drive_to_radiance(r.render(WALK[k], t=0.0)) for k in CHECK]
    assert r.last_full_render  # no far layer: every mesh drawn each frame
    r.release()
    return frames


def walk(renderer, poses):
    out = np.empty((20350, 2), np.uint16)
    frames = []
    for k, pose in enumerate(poses):
        renderer.render(pose, out=out, t=0.0)
        if k in CHECK:
            frames.append(drive_to_radiance(out))
    return frames


def test_cube_taps_interpolate_a_world_aligned_atlas():
    n = 64
    texel_dirs = cubemap.atlas_directions(n)
    smooth = np.stack([0.5 + 0.4 * texel_dirs[:, 0], 0.5 + 0.4 * texel_dirs[:, 2], 0.3 + 0.2 * texel_dirs[:, 1],
                       np.full(len(texel_dirs), 0.7)], axis=1)
    atlas = np.rint(smooth * 65535).astype(np.uint16)
    rng = np.random.default_rng(0)
    d = rng.normal(size=(5000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    taps, weights = cube_taps(d, n)
    assert taps.min() >= 0 and taps.max() < 6 * n * n
    np.testing.assert_allclose(weights.sum(axis=1), 1.0, atol=1e-6)
    out = np.empty((len(d), 4), np.float32)
    gather_bilinear(atlas, taps, weights, out)
    expected = np.stack([0.5 + 0.4 * d[:, 0], 0.5 + 0.4 * d[:, 2], 0.3 + 0.2 * d[:, 1], np.full(len(d), 0.7)], 1)
    # a linear function of direction, sampled on a gnomonic grid: bilinear error of order a texel (1.8 deg)
    assert np.abs(out - expected).max() < 0.4 * math.radians(cubemap.largest_texel_deg(n))


def test_allowed_displacement_bounds_the_parallax():
    r, err = 3.0, math.radians(0.25)
    d = allowed_displacement(r, err)
    # content at the near radius seen from an eye moved by d: displacement d / (r - d) radians
    assert d / (r - d) == pytest.approx(math.tan(err), rel=1e-9)
    assert 0.012 < d < 0.014


def test_a_displacement_does_not_lead_the_layers_built_after_it_off_along_it():
    """An ant walking at 3 cm/s along +y is displaced 0.5 m along +x: the velocity that leads the next layers
    stays the walk's (it was 100 m/s along the jump at the next frame, and 0.2 m/s a third of a second later)."""
    period, speed, max_shift = 1 / 190, 0.03, allowed_displacement(2.0, math.radians(0.5))
    velocity = EyeVelocity(max_shift)
    eye, t = np.zeros(3), 0.0
    for frame in range(400):
        if frame == 200:
            eye = eye + [0.5, 0.0, 0.0]
        velocity.update(eye, t)
        eye, t = eye + [0.0, speed * period, 0.0], t + period
        if frame >= 200:
            assert np.allclose(velocity.value, [0.0, speed, 0.0], atol=1e-4)
    assert np.allclose(velocity.lead(0.2, 0.5 * max_shift), [0.0, speed * 0.2, 0.0], atol=1e-4)
    assert np.isclose(np.linalg.norm(velocity.lead(10.0, 0.5 * max_shift)), 0.5 * max_shift)


class _Builder:
    """The async builder's process, faked at its pipe (`far_layer._Worker`): records what it is sent and answers a
    build when told, as the process does."""

    def __init__(self, far_field, args, nice, process=None):
        from antarium.renderers.far_layer import TABLE_SLOTS

        self.tables = [(np.zeros((*far_field.grid.shape, 2), np.uint16),) * 2 for _ in range(TABLE_SLOTS)]
        self.sent, self.done, self.busy, self.error = [], [], False, None

    def send(self, message):
        self.sent.append(message)
        self.busy = self.busy or message[0] == "build"

    def finish(self):
        _, eye, generation, index = next(m for m in reversed(self.sent) if m[0] == "build")
        self.done.append((eye, generation, index))
        self.busy = False

    def results(self):
        out, self.done = self.done, []
        return out


def _async_layer(dome, monkeypatch):
    """An async far layer on the faked builder, with a first layer in use at the origin."""
    from antarium.renderers import far_layer
    from antarium.renderers.farfield import FarFieldTable, TableGrid

    monkeypatch.setattr(far_layer, "_Worker", _Builder)
    grid = TableGrid(dome.directions, math.radians(3.0))
    table = FarFieldTable(grid, *far_layer._empty_tables(grid))
    layer = far_layer.FarLayer("async", None, {}, table, 2.0, math.radians(0.5), 64, 1.0, 0.01,
                               lambda eye, radius: np.zeros(1, bool))
    eye = np.zeros(3)
    assert layer.current(eye) is None and layer._worker.sent[-1][0] == "build"
    layer._worker.finish()
    assert layer.current(eye) is not None
    return layer, layer._worker, eye


def test_the_frames_own_layer_is_renewed_before_one_asked_for_ahead(dome, monkeypatch):
    """An edit asked for ahead while the layer in use is due for renewal: the builder renews it first (without the
    edit, which it gets only with the edit's own layer), then builds the edit's layer; so a frame never runs out
    of layer while the builder is busy with the edit's (it sent the edit, then the edit's layer, first)."""
    layer, builder, eye = _async_layer(dome, monkeypatch)
    walked = eye + [0.5 * layer.max_shift, 0.0, 0.0]  # due for renewal, still usable
    assert layer.edit_ahead(("hide", "tree"), walked)
    assert layer.current(walked) is not None
    assert [m[0] for m in builder.sent] == ["build", "build"] and builder.sent[-1][2] == 0  # renewal, old objects
    builder.finish()
    assert layer.current(walked) is not None
    assert [m[0] for m in builder.sent[2:]] == ["edit", "build"] and builder.sent[-1][2] == 1  # the edit's layer
    builder.finish()
    assert layer.current(walked) is not None and layer.edit_ready(walked)
    layer.edit(("hide", "tree"))
    assert layer.current(walked) is not None and layer.generation == 1


def test_a_layer_held_for_a_displacement_never_stops_renewal(dome, monkeypatch):
    """A layer prefetched for a displacement the eye never makes (it was applied without its layer, and the eye
    walked on) stays held, but the frames' own layer is still renewed as the eye walks, into a third table (with
    two, renewal waited for the held layer to be used: every frame was drawn in full until the next edit)."""
    layer, builder, eye = _async_layer(dome, monkeypatch)
    layer.prefetch(eye + [0.5, 0.0, 0.0])
    assert layer.current(eye) is not None
    builder.finish()
    assert layer.current(eye) is not None and layer.ready_at(eye + [0.5, 0.0, 0.0])  # held
    for step in range(1, 6):  # walking on, 0.9 of the allowed shift at a time (beyond any lead's renewal distance)
        walked = eye + [0.0, step * 0.9 * layer.max_shift, 0.0]
        assert layer.current(walked) is not None, f"no layer after {step} steps"
        assert builder.busy, "renewal not asked for"
        builder.finish()
    used = {m[3] for m in builder.sent if m[0] == "build"}
    assert used == {0, 1, 2} and layer.ready_at(eye + [0.5, 0.0, 0.0])


def test_sync_far_layer_matches_full_renders_along_a_walk(dome, reference):
    r = Renderer(dome, far_layer="sync")
    r.set_scene(small_habitat())
    frames = walk(r, WALK)
    status = r.far_layer_status()
    assert not r.last_full_render
    r.release()
    diff = np.concatenate([np.abs(a - b).sum(axis=1) for a, b in zip(frames, reference, strict=True)])
    # near meshes at 96 texels, far ones from the layer at 192: LED values within a few % of the full render
    assert diff.mean() < 0.004 and np.percentile(diff, 99) < 0.06
    # every frame used a layer; a 10 cm walk needs a new one every <= 17 mm (0.5 deg at the default 2 m)
    assert status["full_frames"] == 0 and status["layer_frames"] == len(WALK)
    walked = math.hypot(WALK[-1].x - WALK[0].x, WALK[-1].y - WALK[0].y)
    shift = allowed_displacement(r.near_radius, r.far_layer_error)
    assert walked / shift <= status["builds"] <= 2 * walked / shift + 2


def test_far_layer_follows_object_edits(dome):
    scene = small_habitat()
    tree = scene.objects["tree_0"]
    moved = SceneObject(tree.mesh, position=(6.0, 0.0, 0.0), yaw=0.0)  # 6 m ahead: in the far layer
    pose = Pose(0.0, 0.0, 0.01, 0.0)
    ref = Renderer(dome)
    ref.set_scene(small_habitat())
    ref.move_object("tree_0", position=moved.position, yaw=0.0)
    expected = drive_to_radiance(ref.render(pose, t=0.0))
    ref.remove_object("tree_0")
    expected_removed = drive_to_radiance(ref.render(pose, t=0.0))
    ref.release()

    r = Renderer(dome, far_layer="sync")
    r.set_scene(scene)
    before = drive_to_radiance(r.render(pose, t=0.0))
    r.move_object("tree_0", position=moved.position, yaw=0.0)
    after = drive_to_radiance(r.render(pose, t=0.0))
    r.remove_object("tree_0")
    removed = drive_to_radiance(r.render(pose, t=0.0))
    builds = r.far_layer_status()["builds"]
    r.release()
    ahead = (dome.azimuth > -0.3) & (dome.azimuth < 0.3) & (dome.elevation > 0.05)
    assert np.abs(after - before)[ahead].sum(axis=1).max() > 0.2  # the tree appeared in front
    assert np.abs(after - expected).sum(axis=1).mean() < 0.004
    assert np.abs(removed - expected_removed).sum(axis=1).mean() < 0.004
    assert builds == 3  # one layer per edit, none in between


def test_async_far_layer_takes_over_and_survives_its_process(dome, reference):
    r = Renderer(dome, far_layer="async")
    try:
        r.set_scene(small_habitat())
        out = np.empty((20350, 2), np.uint16)
        deadline = time.monotonic() + 60
        while r.layer_frames == 0 and time.monotonic() < deadline:  # full frames until the first layer is in
            r.render(WALK[0], out=out, t=0.0)
            time.sleep(0.005)
        assert r.layer_frames == 1 and r.full_frames >= 1
        first = drive_to_radiance(out)
        assert np.abs(first - reference[0]).sum(axis=1).mean() < 0.004
        # an eye jump far beyond the bound: drawn in full at once (never a stale layer)
        full_before = r.full_frames
        r.render(Pose(5.0, 5.0, 0.01, 0.0), out=out, t=0.0)
        assert r.full_frames == full_before + 1
        # the builder process dies: reported, and every frame is drawn in full from then on
        os.kill(r.far_layer_status()["pid"], signal.SIGKILL)
        deadline = time.monotonic() + 10
        while not r.far_layer_status()["error"] and time.monotonic() < deadline:
            r.render(Pose(5.0, 5.0, 0.01, 0.0), out=out, t=0.0)
            time.sleep(0.01)
        status = r.far_layer_status()
        assert "far-layer process gone" in status["error"]
        frame = r.render(Pose(5.0, 5.0, 0.01, 0.0), t=0.0)
        assert frame.any() and r.far_layer_status()["full_frames"] == status["full_frames"] + 1
    finally:
        r.release()


def test_async_release_stops_the_process_and_frees_the_tables(dome):
    r = Renderer(dome, far_layer="async")
    r.set_scene(small_habitat())
    pid = r.far_layer_status()["pid"]
    # the two table slots the builder writes into: the shared-memory files its address space maps
    assert wait_for(lambda: len(_shared_memory_of(pid)) >= 2, 30.0)
    tables = _shared_memory_of(pid)
    r.release()
    with pytest.raises(ProcessLookupError):  # ended and reaped
        os.kill(pid, 0)
    assert not any(t.exists() for t in tables)


def _shared_memory_of(pid: int) -> set[Path]:
    maps = Path(f"/proc/{pid}/maps").read_text().splitlines()
    return {Path(line.split(maxsplit=5)[5]) for line in maps if "/dev/shm/" in line}


@pytest.mark.parametrize("kwargs, message", [
    ({"far_layer": "sometimes"}, "far_layer must be one of off, sync, async"),
    ({"far_layer": "sync", "near_radius": 0.0}, "near_radius must be a positive number of metres"),
    ({"far_layer": "sync", "far_layer_error_deg": 10.0}, "far_layer_error_deg must be in (0, 5]"),
    ({"far_layer": "sync", "layer_face_size": 8}, "layer_face_size must be an integer in 16..2048"),
])
def test_bad_far_layer_settings_are_refused(dome, kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)").replace("]", r"\]")):
        Renderer(dome, **kwargs)


def test_scenes_without_meshes_or_with_a_turning_far_field_have_no_layer(dome):
    r = Renderer(dome, far_layer="sync")
    try:
        r.set_scene("horizon")
        r.render(Pose(0, 0, 0.01, 0), t=0.0)
        assert r.far_layer_status()["mode"] == "off"
        r.set_scene(small_habitat())
        assert r.far_layer_status()["mode"] == "sync"
    finally:
        r.release()


def test_a_frame_never_waits_for_a_helper_that_has_not_started_its_work(dome):
    import threading

    r = Renderer(dome, far_layer="sync")
    r.set_scene(small_habitat())
    expected = r.render(WALK[3], t=0.0).copy()
    before = r.helper_misses  # a busy machine may already have made the first frame take its work back
    release = threading.Event()
    r._helper_thread().submit(release.wait, 30.0)  # the helper held off (on a rig: its CPU or the GIL taken)
    try:
        held_off = r.render(WALK[3], t=0.0).copy()
    finally:
        release.set()
    # the far-field lookup and the helper's half of the sampling were taken back and done by the caller
    assert r.helper_misses == before + 2
    np.testing.assert_array_equal(held_off, expected)
    np.testing.assert_array_equal(r.render(WALK[3], t=0.0), expected)
    r.release()


def test_an_edit_sent_ahead_and_withdrawn_is_undone_in_the_builder(dome, monkeypatch):
    """A new far field sent ahead (a `sky` change being prepared) that is then not made: the builder gets the edit
    that restores its field, and no layer built with the withdrawn field is ever used."""
    layer, builder, eye = _async_layer(dome, monkeypatch)
    new, old = ("far", object()), ("far", object())
    assert layer.edit_ahead(new, eye)
    assert layer.current(eye) is not None
    assert [m[0] for m in builder.sent[1:]] == ["edit", "build"] and builder.sent[1][1] is new
    layer.withdraw(new, old)
    assert builder.sent[-1] == ("edit", old) and layer.edit_ready(eye)
    builder.finish()  # the layer with the withdrawn field comes in: never used
    assert layer.current(eye) is None
    assert builder.sent[-1][0] == "build" and builder.sent[-1][2] == layer.generation
    builder.finish()
    assert layer.current(eye) is not None
    layer.withdraw(new, old)  # no longer ahead: nothing
    assert builder.sent[-1][0] == "build"


def _sun_moved(scene):
    """The scene's far-field layers with its sun turned 90 degrees and less polarisation."""
    import dataclasses

    sky = scene.sky
    moved = dataclasses.replace(sky, sun_azimuth=sky.sun_azimuth + math.pi / 2, dop_max=0.3)
    return [moved if layer is sky else layer for layer in scene.far]


@pytest.mark.parametrize(("far_layer", "path"), [("off", "cpu"), ("sync", "cpu"), ("off", "gpu")])
def test_a_new_sky_keeps_the_objects_and_every_edit_made_while_it_was_prepared(dome, far_layer, path, monkeypatch):
    """`set_far` swaps the far field (table, far layer's field; on the GPU path the table the device looks up) and
    nothing else: the meshes are not built again, and an object edit or a contrast made between `prepare_far` and
    the swap stay (the frame equals a full render of the scene with the new sky and the same edits)."""
    import dataclasses

    from antarium.renderers import renderer as renderer_module

    pose = Pose(0.0, 0.0, 0.01, 0.3)
    position = (6.0, 0.0, 0.0)
    base = small_habitat()
    ref = Renderer(dome)
    ref.set_scene(dataclasses.replace(base, far=_sun_moved(base)))
    ref.move_object("tree_0", position=position, yaw=0.0)
    ref.set_contrast(0.8)
    expected = drive_to_radiance(ref.render(pose, t=0.0))
    ref.release()

    r = Renderer(dome, far_layer=far_layer, path=path)
    try:
        r.set_scene(small_habitat())
        before = drive_to_radiance(r.render(pose, t=0.0))
        prepared = r.prepare_far(_sun_moved(r.scene))
        r.move_object("tree_0", position=position, yaw=0.0)
        r.set_contrast(0.8)

        def no_new_meshes(*args, **kwargs):
            raise AssertionError("the meshes were built again for a new sky")

        monkeypatch.setattr(renderer_module, "MeshBuffers", no_new_meshes)
        r.set_far(prepared)
        after = drive_to_radiance(r.render(pose, t=0.0))
        assert r.scene.sky.dop_max == 0.3 and "tree_0" in r.scene.objects
        assert not r.last_full_render or far_layer == "off"
    finally:
        r.release()
    up = dome.elevation > math.radians(30)
    assert np.abs(after - before)[up].sum(axis=1).mean() > 0.01  # the sky changed
    assert np.abs(after - expected).sum(axis=1).mean() < 0.004


def test_a_new_sky_drawn_from_a_cube_texture(dome):
    """A renderer that draws the far field from a cube texture (no table) gets the new sky's texture at the swap."""
    import dataclasses

    from antarium.renderers.library import build_scene

    pose = Pose(0.0, 0.0, 0.0, 0.0)
    base = build_scene("sky")
    ref = Renderer(dome, fast_far_field=False)
    ref.set_scene(dataclasses.replace(base, far=_sun_moved(base)))
    expected = ref.render(pose, t=0.0).astype(np.int64)
    ref.release()
    r = Renderer(dome, fast_far_field=False)
    try:
        r.set_scene(build_scene("sky"))
        before = r.render(pose, t=0.0).astype(np.int64)
        r.set_far(r.prepare_far(_sun_moved(r.scene)))
        after = r.render(pose, t=0.0).astype(np.int64)
    finally:
        r.release()
    assert np.abs(after - before).max() > 1000 and np.abs(after - expected).max() <= 1


@pytest.mark.parametrize("kind", ["far", "move", "hide"])
def test_another_edit_withdraws_an_edit_sent_ahead_first(dome, monkeypatch, kind):
    """An object edit made while another edit is ahead in the builder (a sky change, an object moved or removed,
    being prepared; the other edit another client's command): the builder undoes the edit ahead (the field on
    the dome, the object where it is, the object shown) before it gets the other, so that no layer shows the edit
    ahead early (until 2026-11-26 only a sky was withdrawn: a move or removal could show up to 2 s early); the
    edit's own swap then sends it again."""
    from antarium.renderers import far_layer
    from antarium.renderers.farfield import FarFieldTable, TableGrid
    from antarium.renderers.scene import SceneObject

    layer, builder, eye = _async_layer(dome, monkeypatch)
    grid = TableGrid(dome.directions, math.radians(3.0))
    shown, new = (FarFieldTable(grid, *far_layer._empty_tables(grid)) for _ in range(2))
    bush = SceneObject(None, position=(1.0, 0.0, 0.0))
    r = Renderer.__new__(Renderer)  # the renderer's bookkeeping only: its layer, table and scene's objects
    r._layer, r._table, r.scene = layer, shown, SimpleNamespace(objects={"bush": bush})
    ahead, undo = {"far": (("far", new), ("far", shown)),
                   "move": (("move", "bush", SceneObject(None, position=(3.0, 0.0, 0.0))), ("move", "bush", bush)),
                   "hide": (("hide", "bush"), ("show", "bush"))}[kind]
    assert layer.edit_ahead(ahead, eye)
    assert layer.current(eye) is not None and builder.sent[-2] == ("edit", ahead)
    r._layer_edit(("hide", "tree"))
    assert builder.sent[-2:] == [("edit", undo), ("edit", ("hide", "tree"))] and layer.ahead is None
    r._layer_edit(ahead)  # the edit's swap
    assert builder.sent[-1] == ("edit", ahead)


def test_a_new_sky_withdrawn_by_the_renderer_is_undone_in_the_builder(dome, monkeypatch):
    """`Renderer.withdraw_far` (a sky change that will not be made) gives the builder the field on the dome back.
    Until 2026-11-26 it named the edit ahead by a tuple of its own, which `FarLayer.withdraw` did not take for the
    one ahead (it compared identities): nothing was withdrawn, and the layers went on with a sky never shown."""
    from antarium.renderers import far_layer
    from antarium.renderers.farfield import FarFieldTable, TableGrid

    layer, builder, eye = _async_layer(dome, monkeypatch)
    grid = TableGrid(dome.directions, math.radians(3.0))
    shown, new = (FarFieldTable(grid, *far_layer._empty_tables(grid)) for _ in range(2))
    r = Renderer.__new__(Renderer)  # the renderer's bookkeeping only: its layer and table
    r._layer, r._table = layer, shown
    assert layer.edit_ahead(("far", new), eye)
    assert layer.current(eye) is not None and builder.sent[-2] == ("edit", ("far", new))
    r.withdraw_far(SimpleNamespace(table=new))
    assert builder.sent[-1] == ("edit", ("far", shown)) and layer.ahead is None


def test_a_hidden_object_is_shown_again_by_the_builder(dome):
    """The builder's "show" edit undoes its "hide": a tree beyond the near radius (drawn by the far layer alone)
    removed, then shown again in the layer, gives the frame from before."""
    pose = Pose(0.0, 0.0, 0.01, 0.0)
    r = Renderer(dome, far_layer="sync")
    try:
        r.set_scene(small_habitat())  # tree_0 is 7.6 m from the eye
        before = r.render(pose, t=0.0).copy()
        r.remove_object("tree_0")
        removed = r.render(pose, t=0.0).copy()
        r._layer.edit(("show", "tree_0"))
        shown = r.render(pose, t=0.0)
        assert r.far_layer_status()["layer_frames"] == 3
    finally:
        r.release()
    assert np.abs(removed.astype(int) - before).max() > 10_000
    np.testing.assert_array_equal(shown, before)
