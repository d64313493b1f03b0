"""Scene loads, displacements and object edits are prepared off the frame loop and swapped in between two frames
(issue 20, point 1): the scene is parsed and built in its own process while frames go on, handed over in shared
memory, its meshes uploaded a slice per frame, and the reply comes when the new scene is on the dome with its far
layer; a displacement (an object edit) waits for the far layer at its target (with the edit). No frame is drawn
in full for any of them. Real renderer (EGL), async far layer."""

import mmap
import threading

import numpy as np
import pytest
from conftest import wait_for

from antarium.config import resolve
from antarium.renderers import library, meshbuffers
from antarium.renderers.prepared import SceneSettings
from antarium.server import Server

FRAMES_DURING_BUILD = 10


def small_renderer(render_cfg, clock=None):
    from antarium.renderers import Renderer

    return Renderer(face_size=64, layer_face_size=64, clock=clock, far_layer="async")


SMALL_HABITAT = {"scene": "habitat", "n_tussocks": 60, "n_stones": 20, "n_bushes": 3, "n_trees": 2}


def _serve(tmp_path, scene):
    config = resolve({"rig": {"name": "tswap"}, "bus": {"enabled": False}, "log": {"dir": str(tmp_path / "logs")},
                      "link": {"interface": "virtual"}, "loop": {"rate_hz": 100.0, "closed_loop": False},
                      "render": {"scene": scene}})
    return Server(config, renderer_factory=small_renderer, echo=lambda line: None).start_thread()


@pytest.fixture
def server(tmp_path):
    server = _serve(tmp_path, "horizon")
    yield server
    server.stop()


@pytest.fixture(scope="module")
def habitat_server(tmp_path_factory):
    server = _serve(tmp_path_factory.mktemp("swap"), SMALL_HABITAT)
    yield server
    server.stop()


def _no_full_frames_through(server, command: str, params: dict) -> None:
    """Run `command`, then 5 frames: none of them (nor any while it was prepared) drawn in full."""
    full_before = server.renderer.far_layer_status()["full_frames"]
    server.command(command, params)
    frames = server.loop.frame
    assert wait_for(lambda: server.loop.frame >= frames + 5, 10.0)
    assert server.renderer.far_layer_status()["full_frames"] == full_before


def test_a_displacement_waits_for_the_far_layer_at_its_target(habitat_server):
    for step in (0.5, -0.5, 0.5):
        pose = habitat_server.loop.pose
        _no_full_frames_through(habitat_server, "set_pose", {"x": pose.x + step, "y": pose.y})
        assert habitat_server.loop.pose.x == pytest.approx(pose.x + step)


def test_an_object_edit_waits_for_the_far_layer_with_it(habitat_server):
    objects = habitat_server.renderer.scene.objects
    name = next(n for n in objects if n.startswith("bush"))
    for dx in (0.2, -0.2, 0.2):
        x, y, z = (float(c) for c in objects[name].position)
        _no_full_frames_through(habitat_server, "scene_edit",
                                {"op": "move_object", "args": {"name": name, "position": [x + dx, y, z]}})
        assert float(habitat_server.renderer.scene.objects[name].position[0]) == pytest.approx(x + dx)
    _no_full_frames_through(habitat_server, "scene_edit", {"op": "remove_object", "args": {"name": name}})
    assert name not in habitat_server.renderer.scene.objects


def test_the_old_scenes_gl_objects_are_released_one_per_frame_after_a_load(habitat_server, monkeypatch):
    """Not in the swap (releasing a large buffer took the NVIDIA driver up to 10 ms): one object in each of the next
    frames' idle time, in the loop's thread."""
    renderer = habitat_server.renderer
    calls = []
    release = renderer.release_retired

    def recorded():
        calls.append((threading.current_thread(), habitat_server.loop.frame))
        return release()

    monkeypatch.setattr(renderer, "release_retired", recorded)
    habitat_server.command("load_scene", {"scene": SMALL_HABITAT})
    assert wait_for(lambda: renderer.retired == 0, 10.0)
    assert len(calls) >= 4 and {t for t, _ in calls} == {habitat_server._loop_thread}
    assert len({f for _, f in calls}) == len(calls)  # one a frame


def test_an_object_move_computes_its_vertices_beside_the_loop(habitat_server, monkeypatch):
    """The loop's thread only uploads a moved object's vertices: computing them (5-8 ms for the habitat's ground,
    which held the next frame that long) is done in the command's thread, while frames go on."""
    from antarium.renderers.meshbuffers import MeshBuffers

    threads = []
    moved = MeshBuffers.moved

    def recorded(self, name, obj):
        threads.append(threading.current_thread())
        return moved(self, name, obj)

    monkeypatch.setattr(MeshBuffers, "moved", recorded)
    objects = habitat_server.renderer.scene.objects
    name = next(n for n in objects if n.startswith("bush"))
    x, y, z = (float(c) for c in objects[name].position)
    habitat_server.command("scene_edit", {"op": "move_object", "args": {"name": name, "position": [x + 0.3, y, z]}})
    assert float(habitat_server.renderer.scene.objects[name].position[0]) == pytest.approx(x + 0.3)
    assert len(threads) == 1 and threads[0] is not habitat_server._loop_thread


def _buffer_owner(array):
    """The object that owns an array's memory (following views)."""
    while isinstance(array, np.ndarray) and array.base is not None:
        array = array.base
    return array.obj if isinstance(array, memoryview) else array


def test_a_scene_is_built_in_its_own_process_while_frames_go_on_and_shown_with_its_far_layer(server, monkeypatch):
    def not_here(*args, **kwargs):
        raise AssertionError("the scene was built in the server's process")

    monkeypatch.setattr(library, "build_scene", not_here)
    monkeypatch.setattr(SceneSettings, "build", not_here)
    steps = []  # (thread, frame) of each slice of the meshes' upload
    upload_step = server.renderer.upload_step

    def recorded(prepared):
        steps.append((threading.current_thread(), server.loop.frame))
        return upload_step(prepared)

    monkeypatch.setattr(server.renderer, "upload_step", recorded)
    monkeypatch.setattr(meshbuffers, "UPLOAD_SLICE_BYTES", 64 << 10)
    full_before = server.renderer.far_layer_status()["full_frames"]
    start = server.loop.frame
    server.command("load_scene", {"scene": SMALL_HABITAT})
    assert server.loop.frame >= start + FRAMES_DURING_BUILD  # frames went on while it was prepared
    objects = server.renderer.scene.objects
    assert server.scene_name.startswith('{"n_bushes": 3') and objects
    # handed over, not copied: the meshes are views of the scene process's shared mapping
    assert all(isinstance(_buffer_owner(o.mesh.vertices), mmap.mmap) for o in objects.values())
    # uploaded a slice per frame, in the loop's thread, before the swap
    assert len(steps) >= 3 and {t for t, _ in steps} == {server._loop_thread}
    assert len({f for _, f in steps}) == len(steps)
    frames = server.loop.frame
    assert wait_for(lambda: server.loop.frame >= frames + 5, 10.0)
    status = server.renderer.far_layer_status()
    assert status["mode"] == "async" and status["layer_frames"] >= 5
    assert status["full_frames"] == full_before  # the far layer was ready when the scene was swapped in


def test_a_failed_load_prepared_off_the_loop_keeps_the_scene(server):
    before = server.renderer.scene
    with pytest.raises(RuntimeError, match="failed to load .*the current scene 'horizon' stays on the dome"):
        server.command("load_scene", {"scene": {"scene": "grating", "period_deg": "wide"}})
    assert server.renderer.scene is before and server.scene_name == "horizon"


def test_a_sky_change_is_built_off_the_loop_while_frames_go_on(server, monkeypatch):
    server.command("load_scene", {"scene": "sky"})
    builds = []  # (thread, frame before, frame after) of each far field made for it
    prepare = server.renderer.prepare_far

    def recorded(far):
        before = server.loop.frame
        out = prepare(far)
        builds.append((threading.current_thread(), before, server.loop.frame))
        return out

    monkeypatch.setattr(server.renderer, "prepare_far", recorded)
    server.command("sky", {"sun_azimuth_deg": 120.0, "dop_max": 0.4})
    assert len(builds) == 1 and builds[0][0] is not server._loop_thread
    assert builds[0][2] > builds[0][1]  # frames went on while its far field was built
    sky = server.renderer.scene.sky
    assert sky.sun_azimuth == pytest.approx(np.radians(120.0)) and sky.dop_max == 0.4
    server.command("load_scene", {"scene": "horizon"})
    with pytest.raises(RuntimeError, match="sky: the current scene 'horizon' has no sky"):
        server.command("sky", {"dop_max": 0.2})


def test_a_scene_loaded_while_a_sky_change_was_prepared_gets_the_change(server, monkeypatch):
    server.command("load_scene", {"scene": "sky"})
    prepare = server.renderer.prepare_far

    def then_another_load(far):
        monkeypatch.undo()  # once: the swap then prepares the change for the new scene itself
        prepared = prepare(far)
        server.loop.call_soon(server.load_scene, "sky").result(10.0)  # a new scene object, sun where it was
        return prepared

    monkeypatch.setattr(server.renderer, "prepare_far", then_another_load)
    server.command("sky", {"sun_elevation_deg": 10.0})
    assert server.renderer.scene.sky.sun_elevation == pytest.approx(np.radians(10.0))
    assert server.renderer.scene.sky.sun_azimuth == pytest.approx(np.radians(135.0))  # the new scene's, kept


def test_a_sky_change_keeps_the_meshes_and_shows_with_its_far_layer(habitat_server):
    meshes = habitat_server.renderer._meshes
    _no_full_frames_through(habitat_server, "sky", {"sun_azimuth_deg": 30.0, "dop_max": 0.5})
    assert habitat_server.renderer.scene.sky.dop_max == 0.5
    assert habitat_server.renderer._meshes is meshes  # nothing of the meshes made again


def test_an_object_edit_made_while_a_sky_change_was_prepared_is_kept(habitat_server, monkeypatch):
    """Stop 28's sky change swapped in a copy of the scene made before the edit: the removed bush came back."""
    renderer = habitat_server.renderer
    name = next(n for n in renderer.scene.objects if n.startswith("bush"))
    prepare = renderer.prepare_far

    def then_an_edit(far):
        monkeypatch.undo()
        prepared = prepare(far)
        habitat_server.command("scene_edit", {"op": "remove_object", "args": {"name": name}})
        return prepared

    monkeypatch.setattr(renderer, "prepare_far", then_an_edit)
    meshes = renderer._meshes  # the edit hides the bush's chunks in these
    habitat_server.command("sky", {"sun_elevation_deg": 25.0, "sun_azimuth_deg": 200.0})
    assert renderer.scene.sky.sun_elevation == pytest.approx(np.radians(25.0))
    assert name not in renderer.scene.objects and renderer._meshes is meshes


def test_a_trial_log_holds_the_state_set_before_its_trial_started(server):
    """Gains, a sky change, a brightness and held polariser angles set before trial_start were in no log (its config
    said gains 1 where the ant ran at 3): the trial_started event holds the state the trial starts in."""
    import json

    from antarium.trial_log import read_table

    server.command("load_scene", {"scene": "sky"})
    server.command("sky", {"sun_azimuth_deg": 120.0})
    server.command("scene_edit", {"op": "set_brightness", "args": {"brightness": 0.5}})
    server.command("gains", {"translation": 3.0, "rotation": 0.25})
    server.command("polarisers", {"angles_deg": [[10.0] * 9] * 55})
    path = server.trial_start("after_settings", {})["path"]
    server.trial_stop()
    events = read_table(path, "events")
    state = json.loads(events["data"][list(events["kind"]).index("trial_started")])["state"]
    assert state["gains"] == {"translation": 3.0, "rotation": 0.25} and state["scene"] == "sky"
    assert state["scene_changes"] == [{"command": "sky", "request": {"sun_azimuth_deg": 120.0}},
                                      {"command": "scene_edit",
                                       "request": {"op": "set_brightness", "args": {"brightness": 0.5}}}]
    assert state["brightness"] == 0.5 and np.allclose(state["polarisers_deg"], 10.0)
    assert {"pose", "scene_rotation_deg", "closed_loop", "tether"} <= set(state)
    server.command("load_scene", {"scene": "horizon"})  # a load ends the scene's edits; the brightness stays
    server.command("polarisers", {"angles_deg": None})
    path = server.trial_start("after_load", {})["path"]
    server.trial_stop()
    events = read_table(path, "events")
    state = json.loads(events["data"][list(events["kind"]).index("trial_started")])["state"]
    assert state["scene_changes"] == [] and state["brightness"] == 0.5 and state["polarisers_deg"] is None
