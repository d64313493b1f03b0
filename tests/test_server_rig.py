"""The server with a real renderer and `antarium emulate` over loopback UDP: outage and restart of the
emulator mid-recording, failed scene loads keeping the previous scene, scene edits and polarisers."""

import os
import signal
import time

import pytest
from conftest import wait_for

import antarium
from antarium import bus
from antarium.client import RigError
from antarium.config import resolve
from antarium.server import Server
from antarium.trial_log import read_table


def small_renderer(render_cfg, clock=None):
    from antarium.renderers import Renderer

    return Renderer(face_size=64, clock=clock)


def _config(tmp_path, rig):
    return resolve({
        "rig": {"name": rig},
        "bus": {"listen": [bus.free_tcp_endpoint()]},
        "log": {"dir": str(tmp_path / "logs"), "flush_s": 0.1},
        "render": {"scene": {"scene": "horizon", "elevation_deg": 5}},
        "link": {"interface": "udp", "spawn_emulator": True},
        "loop": {"rate_hz": 100.0},
    })


def test_emulator_killed_and_restarted_mid_recording(tmp_path):
    config = _config(tmp_path, "tout")
    server = Server(config, renderer_factory=small_renderer, record="outage", echo=lambda line: None)
    server.start_thread()
    try:
        loop = server.loop
        assert wait_for(lambda: loop.telemetry.get("connected") and loop.link_ok and loop.frame > 50, 20.0)
        os.kill(server.emulator.pid, signal.SIGKILL)  # the emulator crashes
        assert wait_for(lambda: not server.emulator.running, 5.0)
        assert wait_for(lambda: not loop.link_ok, 5.0)
        frames_at_outage = loop.frame
        alarms = " ".join(server.status()["alarms"])
        assert "dome link down" in alarms and "emulator process is not running" in alarms
        time.sleep(0.5)
        assert loop.frame > frames_at_outage + 20  # still pacing
        server.emulator.start()
        assert wait_for(lambda: loop.link_ok, 20.0)
    finally:
        server.stop()
    frames = read_table(server.trial_paths[0], "frames")
    assert (frames["frame"][1:] - frames["frame"][:-1] == 1).all()
    assert (frames["link_ok"] == 0).any() and frames["link_ok"][-1] == 1
    kinds = list(read_table(server.trial_paths[0], "events")["kind"])
    assert kinds.index("link_outage") < kinds.index("link_back")


def test_failed_scene_load_keeps_the_previous_scene(tmp_path):
    config = _config(tmp_path, "tscene")
    config.link.interface = "virtual"
    server = Server(config, renderer_factory=small_renderer, echo=lambda line: None).start_thread()
    try:
        with antarium.Rig("tscene", config=config, timeout_s=10.0) as rig:
            before = server.renderer.scene
            for bad, message in [("/nonexistent/world.glb", "failed to load"),
                                 ({"scene": "grating", "period_deg": "wide"}, "failed to load"),
                                 ({"scene": "horizon", "colour_of_sky": 1}, "unknown parameter")]:
                with pytest.raises(RigError, match=message):
                    rig.load_scene(bad) if isinstance(bad, str) else rig.call("load_scene", scene=bad)
                assert server.renderer.scene is before
                assert rig.status()["scene"] == server.scene_name
            state = rig.call("load_scene", scene={"scene": "grating", "period_deg": 20})
            assert "grating" in state["scene"] and server.renderer.scene is not before
            rig.call("scene_edit", op="set_contrast", args={"contrast": 0.5})
            assert server.renderer.scene.contrast == 0.5
            with pytest.raises(RigError, match="unknown argument"):
                rig.call("scene_edit", op="set_contrast", args={"gamma": 2})
            with pytest.raises(RigError, match="contrast"):
                rig.call("scene_edit", op="set_contrast", args={"contrast": -3})
            assert server.renderer.scene.contrast == 0.5
            rig.load_scene("sky")
            rig.sky(sun_azimuth_deg=90, sun_elevation_deg=30)
            assert server.renderer.scene.sky.sun_azimuth == pytest.approx(1.5707963)
            rig.polarisers([[10.0] * 9] * 55)
            assert wait_for(lambda: server.link.telemetry(wait_s=0.1).get("polariser_angles_deg") is not None, 5.0)
            with pytest.raises(RigError, match="55 lists of 9 numbers"):
                rig.polarisers([[10.0] * 9] * 54)
    finally:
        server.stop()
