"""The virtual ant on a served rig, in real time: `antarium serve`'s Server renders and sends its frames over UDP to
the ant's dome (the emulated distributor and panels in the ant's process) and reads the ant's ball from the bus,
where the driver of the ant's emulated USB trackball publishes it; short mode (a few seconds)."""

import json
import math

import numpy as np
import pytest
from conftest import wait_for

from antarium import bus
from antarium.ant.agent import learning_walk
from antarium.ant.eye import EyeParams
from antarium.ant.models import make_model
from antarium.ant.routes import curved_route
from antarium.ant.served import run_served, served_ant, served_config
from antarium.ant.storage import save_model
from antarium.ant.world import virtual_rig
from antarium.server import Server
from antarium.server.emulator_process import free_udp_port
from antarium.trial_log import read_table

ROUTE = curved_route(4, length=0.4, start=(0.5, -0.3))



def _config(tmp_path, tether="free_yaw"):
    return {"rig": {"name": "antserved"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
            "link": {"interface": "udp", "port": free_udp_port("127.0.0.1"), "spawn_emulator": False},
            "locomotion": {"source": "bus"}, "loop": {"tether": tether},
            "render": {"scene": "habitat", "face_size_px": 64}, "log": {"dir": str(tmp_path / "trials")}}


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    model = make_model("antcar", 800)
    with virtual_rig(model, renderer_kwargs={"face_size": 64}) as ant:
        learning_walk(ant, ROUTE, 0.01)
    return save_model(tmp_path_factory.mktemp("model") / "ant.npz", model, EyeParams(), ROUTE.points)


@pytest.mark.parametrize("tether", ["free_yaw", "fixed"])
def test_a_trained_ant_follows_its_route_on_the_served_rig_in_real_time(model_file, tmp_path, tether):
    config = _config(tmp_path, tether)
    lines = []
    with Server(served_config(config), echo=lines.append):
        summary = run_served(model_file, config, tmp_path / "out", start_offset=(0.02, math.radians(10)),
                             max_decisions=25, echo=lines.append)
    assert summary["distance"] > 0.15 and summary["lateral_median"] < 0.05
    assert (tmp_path / "out" / "served_paths.png").stat().st_size > 10_000
    # the server logged the trial as a real one: its frames moved with the ball samples the ant's driver published
    frames = read_table(summary["trial_log"], "frames")
    samples = read_table(summary["trial_log"], "locomotion")
    assert len(samples["seq"]) > 100 and np.all(np.diff(samples["seq"]) == 1)
    steps = np.hypot(np.diff(frames["x"]), np.diff(frames["y"]))
    walked = steps[steps < 0.05].sum()  # without the displacement to the release point (a set_pose command)
    assert walked == pytest.approx(summary["distance"], abs=0.05)
    # each of the ant's decisions in served.json says where it was and the server's frame of that pose: the log agrees
    decisions = [e for e in json.loads((tmp_path / "out" / "served.json").read_text())["events"]
                 if e["kind"] == "ant_decision"]
    row = {int(f): i for i, f in enumerate(frames["frame"])}
    assert len(decisions) == summary["decisions"] and all(e["frame"] in row for e in decisions)
    logged = np.array([(frames["x"][row[e["frame"]]], frames["y"][row[e["frame"]]]) for e in decisions])
    np.testing.assert_allclose([(e["x"], e["y"]) for e in decisions], logged, atol=1e-9)
    # the ant's dome and ball, throughout: the ant is released only once the server has heard its dome answer
    assert frames["link_ok"].all()
    assert frames["locomotion_connected"].all()
    assert any(line.startswith("virtual ant on rig 'antserved'") for line in lines)


def test_the_ant_sees_the_frames_the_server_sends(model_file, tmp_path):
    from antarium.ant.storage import load_model

    model, eye_params, _ = load_model(model_file)
    config = _config(tmp_path)
    with Server(served_config(config), echo=lambda line: None) as server:
        with served_ant(model, config, eye_params) as ant:
            ant.place(*ROUTE.start, 0.0)
            placed = server.loop.frame

            def similarity() -> float:
                """Of the ant's view of the frame its dome holds and of the frame the server sent last."""
                ant.frame()
                leds, sent = ant.read_leds(), server.loop.last_frame
                return np.corrcoef(ant.eye.look(leds).pns()[0], ant.eye.look(sent).pns()[0])[0, 1]

            # on a loaded machine the dome may still hold a frame from before the placement for a few frames
            assert wait_for(lambda: server.loop.frame > placed + 2 and similarity() > 0.95, 10.0)
            assert (ant.position[0], ant.position[1]) == pytest.approx(ROUTE.start, abs=0.01)


@pytest.mark.parametrize(("section", "value", "message"), [
    ("link", {"spawn_emulator": True}, "spawn_emulator = false"),
    ("link", {"interface": "virtual"}, 'interface = "udp"'),
    ("locomotion", {"source": "scripted"}, 'source must be "bus"'),
])
def test_a_config_that_cannot_serve_the_ant_is_refused_naming_the_key(tmp_path, section, value, message):
    config = _config(tmp_path)
    config[section] = {**config[section], **value}
    with pytest.raises(ValueError, match=message):
        served_config(config)


def test_the_ant_dome_settles_on_every_frame_sent_before_it():
    """`DomeHost.settle` returns once the dome handled every datagram queued before it: of frames a link sent in
    a burst, the last is shown (the served ant reads its view only after this); a dome that does not answer in
    time is an error."""
    from antarium.ant.served import DomeHost
    from antarium.firmware_proto.udp import UdpLink
    from antarium.firmware_proto.video import decode_frame, encode_frame

    dome = DomeHost("127.0.0.1", free_udp_port("127.0.0.1"))
    dome.start()
    link = UdpLink(dome.host, dome.port)
    try:
        rng = np.random.default_rng(3)
        # three frames (190 kB): within a default socket receive buffer, so none is dropped on any machine
        frames = [rng.integers(0, 32768, (20350, 2), dtype=np.uint16) for _ in range(3)]
        for frame in frames:
            link.send_frame(frame)
        dome.settle(5.0)
        assert dome.stats()["frames_latched"] == 3
        np.testing.assert_array_equal(dome.led_values(), decode_frame(encode_frame(frames[-1], 0)))
        with dome._lock, pytest.raises(RuntimeError, match="did not answer in 0.2 s"):  # the dome busy throughout
            dome.settle(0.2)
    finally:
        link.close()
        dome.stop()
