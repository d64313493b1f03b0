"""Scene loads and displacements are prepared off the frame loop and swapped in between two frames (issue 20,
point 1): the scene is parsed and built in the command's thread while frames go on, and the reply comes when the
new scene is on the dome with its far layer; a displacement waits for the far layer at its target. No frame is
drawn in full for either. Real renderer (EGL), async far layer."""

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


def test_a_displacement_waits_for_the_far_layer_at_its_target(tmp_path):
    server = _serve(tmp_path, SMALL_HABITAT)
    try:
        for step in (0.5, -0.5, 0.5):
            full_before = server.renderer.far_layer_status()["full_frames"]
            pose = server.loop.pose
            state = server.command("set_pose", {"x": pose.x + step, "y": pose.y})
            assert state["pose"]["x"] == pytest.approx(pose.x + step)
            frames = server.loop.frame
            assert wait_for(lambda: server.loop.frame >= frames + 5, 10.0)
            assert server.renderer.far_layer_status()["full_frames"] == full_before
    finally:
        server.stop()


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
