"""Scene loads, displacements and object edits are prepared off the frame loop and swapped in between two frames
(issue 20, point 1): the scene is parsed and built in the command's thread while frames go on, and the reply comes
when the new scene is on the dome with its far layer; a displacement (an object edit) waits for the far layer at
its target (with the edit). No frame is drawn in full for any of them. Real renderer (EGL), async far layer."""

import threading

import pytest
from conftest import wait_for

from antarium.config import resolve
from antarium.renderers import library
from antarium.renderers.habitat import habitat_scene
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


def test_a_scene_is_built_while_frames_go_on_and_shown_with_its_far_layer(server, monkeypatch):
    seen = {}

    def watched(params):
        """A habitat whose building waits until the loop has run frames meanwhile (it never does if the loop
        itself is building it)."""
        seen["thread"] = threading.current_thread()
        start = server.loop.frame
        seen["frames_went_on"] = wait_for(lambda: server.loop.frame >= start + FRAMES_DURING_BUILD, 10.0)
        return habitat_scene(n_tussocks=60, n_stones=20, n_bushes=3, n_trees=2)

    monkeypatch.setitem(library.SCENES, "watched", watched)
    full_before = server.renderer.far_layer_status()["full_frames"]
    server.command("load_scene", {"scene": "watched"})
    assert seen["thread"] is not server._loop_thread and seen["frames_went_on"]
    assert server.scene_name == "watched" and server.renderer.scene.objects
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
