"""The server on the bus, driven through `antarium.Rig`: commands, refusals with state unchanged, streams,
trials, access control. Pose-only rig (no renderer, no dome link): the bus and command paths are real."""

import json
import math
import time

import pytest
from conftest import wait_for

import antarium
from antarium import bus
from antarium.client import RigError
from antarium.config import LocomotionSection, resolve
from antarium.server import Server
from antarium.trial_log import read_table


def _config(tmp_path, rig="tb", **bus_extra):
    return resolve({
        "rig": {"name": rig},
        "bus": {"listen": [bus.free_tcp_endpoint()], **bus_extra},
        "log": {"dir": str(tmp_path / "logs"), "flush_s": 0.1},
        "locomotion": {"source": "scripted", "speed": 0.02},
    })


@pytest.fixture
def served(tmp_path):
    config = _config(tmp_path)
    server = Server(config, renderer_factory=None, link=False).start_thread()
    rig = antarium.Rig("tb", config=config, timeout_s=5.0).connect()
    yield server, rig
    rig.close()
    server.stop()


def test_commands_change_the_state_and_reply_with_it(served):
    server, rig = served
    state = rig.closed_loop(False)
    assert state["closed_loop"] is False
    state = rig.set_pose(1.0, 2.0, heading_deg=90)
    assert state["pose"]["x"] == 1.0 and state["pose"]["heading_deg"] == pytest.approx(90)
    state = rig.rotate_scene(90)
    assert state["pose"]["heading_deg"] == pytest.approx(0.0, abs=1e-9)
    assert state["scene_rotation_deg"] == pytest.approx(90)
    rig.gains(translation=2.0)
    rig.tether("fixed")
    assert server.loop.gain_translation == 2.0 and server.loop.tether == "fixed"
    assert wait_for(lambda: rig.latest() is not None and rig.latest().pose.x == 1.0, 3.0)
    assert rig.pose().y == 2.0
    state = rig.reset_origin()
    assert state["pose"]["x"] == 0.0 and state["scene_rotation_deg"] == 0.0


@pytest.mark.parametrize("command, params, message", [
    ("rotate_scene", {"deg": "ninety"}, "must be a finite number"),
    ("rotate_scene", {}, "missing parameter 'deg'"),
    ("set_pose", {"x": 1.0, "y": 2.0, "heading": 3}, "unknown parameter"),
    ("gains", {"translation": 1e9}, "must be in"),
    ("tether", {"tether": "loose"}, "must be one of"),
    ("closed_loop", {"on": 1}, "true or false"),
    ("load_scene", {"scene": "/nonexistent/world.glb"}, "no renderer"),
    ("trial_stop", {}, "no trial is running"),
])
def test_bad_commands_are_refused_with_the_state_unchanged(served, command, params, message):
    server, rig = served
    before = rig.status()
    with pytest.raises(RigError, match=message):
        rig.call(command, **params)
    after = rig.status()
    for key in ("pose", "closed_loop", "tether", "gains", "scene_rotation_deg", "trial", "scene"):
        if key == "pose" and before["closed_loop"]:
            continue  # the walker moves on in closed loop
        assert after[key] == before[key], key


def test_unknown_command_and_bad_json_are_refused(served):
    server, rig = served
    replies = list(rig.session.get(bus.rig_key("tb", "cmd", "fly"), payload=b"{}", timeout=5))
    assert json.loads(replies[0].err.payload.to_bytes())["error"].startswith("unknown command 'fly'")
    replies = list(rig.session.get(bus.command_key("tb", "set_pose"), payload=b"{x:", timeout=5))
    assert "not JSON" in json.loads(replies[0].err.payload.to_bytes())["error"]


def test_payloads_that_are_not_json_are_refused_with_a_reply_and_logged(served):
    """A payload nested too deeply for the JSON reader got no reply at all (a RecursionError in zenoh's callback:
    the client waited for its timeout), and no refusal of a payload that is not JSON reached the trial's commands
    table (docs/logs.md: every command received during the trial, refused ones too)."""
    server, rig = served
    cases = [(b"[" * 100_000 + b"]" * 100_000, "(nested too deeply)"),
             (b"hello", "(Expecting value: line 1 column 1 (char 0))"),
             (b'{"x": ' + b"1" * 5000 + b"}", "(a number too long to read)"),
             (b'{"x": "\xc3\x28"}', "('utf-8' codec can't decode byte 0xc3 in position 7: invalid continuation byte)")]
    with rig.trial("raw") as path:
        for payload, why in cases:
            replies = list(rig.session.get(bus.command_key("tb", "set_pose"), payload=payload, timeout=5))
            assert json.loads(replies[0].err.payload.to_bytes())["error"] == (
                f"set_pose: the payload must be a JSON object of parameters; it is not JSON {why}")
        assert rig.status()["trial"] == "raw"  # and the server still answers
    commands = read_table(path, "commands")
    refused = [(n, json.loads(r)) for n, r, ok in zip(commands["name"], commands["request"], commands["ok"],
                                                     strict=True) if not ok]
    assert [n for n, _ in refused] == ["set_pose"] * 4
    assert refused[1][1] == {"payload": "hello"} and len(refused[0][1]["payload"]) == 203  # cut to 200 + "..."


def test_trial_records_frames_commands_and_metadata(served, tmp_path):
    server, rig = served
    with rig.trial("homing one", ant=3, colony="M. croslandi") as path:
        rig.rotate_scene(-90)
        with pytest.raises(RigError):
            rig.rotate_scene(float("nan"))
        rig.wait(0.3)
    frames = read_table(path, "frames")
    assert len(frames["frame"]) >= 30
    commands = read_table(path, "commands")
    names = list(commands["name"])
    assert names[0] == "trial_start" and "rotate_scene" in names and names[-1] == "trial_stop"
    assert list(commands["ok"]).count(0) == 1  # the refused rotation is logged as refused
    events = list(read_table(path, "events")["kind"])
    assert "scene_rotated" in events and "trial_started" in events and "trial_stopped" in events
    with pytest.raises(RigError, match="no trial is running"):
        rig.stop_trial()


def test_status_and_streams(served):
    server, rig = served
    poses, events = [], []
    rig.on_pose(poses.append)
    rig.on_event(events.append)
    rig.rotate_scene(10)
    assert wait_for(lambda: len(poses) > 20 and any(e["kind"] == "scene_rotated" for e in events), 5.0)
    frames = [p.frame for p in poses]
    assert frames == sorted(frames)
    status = rig.status()
    assert status["rig"] == "tb" and status["frames"] > 0 and status["target_rate_hz"] == 190.0
    assert "latency" in status and status["locomotion"]["connected"] is True
    received = []
    sub = rig.session.declare_subscriber(bus.status_key("tb"), lambda s: received.append(s))
    assert wait_for(lambda: len(received) >= 1, 3.0)
    sub.undeclare()
    assert json.loads(received[0].payload.to_bytes())["rig"] == "tb"


def test_no_server_gives_a_clear_error(tmp_path):
    config = _config(tmp_path, rig="nobody")
    with pytest.raises(RigError, match="no antarium server for rig 'nobody'"):
        antarium.Rig("nobody", config=config, timeout_s=0.5).connect()


ACL = """{
  enabled: true,
  default_permission: "deny",
  rules: [{id: "all", messages: ["put", "delete", "declare_subscriber", "query", "reply", "declare_queryable",
            "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
           flows: ["ingress", "egress"], permission: "allow", key_exprs: ["antarium/**"]}],
  subjects: [{id: "operators", zids: ["%s"]}],
  policies: [{rules: ["all"], subjects: ["operators"]}],
}"""


def test_access_control_refuses_an_unlisted_peer(tmp_path):
    import zenoh

    listed = "a1b2c3d4e5f6a7b8"
    acl = tmp_path / "acl.json5"
    acl.write_text(ACL % listed)
    config = _config(tmp_path, rig="tacl", access_control=str(acl))
    server = Server(config, renderer_factory=None, link=False).start_thread()
    try:
        def client(zid):
            conf = bus.session_config(config.bus, "client")
            conf.insert_json5("id", json.dumps(zid))
            return zenoh.open(conf)

        with client(listed) as ok_session:
            rig = antarium.Rig("tacl", config=config, session=ok_session, timeout_s=3.0).connect()
            assert rig.rotate_scene(45)["scene_rotation_deg"] == pytest.approx(45)
        with client("f0e0d0c0b0a0908") as other:
            with pytest.raises(RigError, match="no antarium server"):  # it cannot even see the server
                antarium.Rig("tacl", config=config, session=other, timeout_s=1.0).connect()
            replies = list(other.get(bus.command_key("tacl", "rotate_scene"), payload=b'{"deg": 45}', timeout=1.0))
            assert replies == []  # the query was dropped by the server's access control
        assert math.degrees(server.loop.scene_rotation) == pytest.approx(45)
    finally:
        server.stop()


def test_locomotion_from_the_bus_drives_the_closed_loop(tmp_path):
    from antarium.locomotion import BallSample, wire

    config = _config(tmp_path, rig="tloco")
    config.locomotion = LocomotionSection.read({"source": "bus", "timeout_s": 5.0})
    server = Server(config, renderer_factory=None, link=False).start_thread()
    try:
        with bus.open_session(config.bus, "client") as trackball:
            pub = bus.locomotion_publisher(trackball, "tloco")  # the trackball driver's: blocks, never drops
            assert wait_for(lambda: server.source.received == 0 and server.loop.frame > 5, 5.0)
            seq = 0  # still samples until the route is up (a sample put before it is not delivered)
            while server.source.received == 0 and seq < 400:
                pub.put(wire.encode(BallSample(0.0, seq, (0.0, 0.0, 0.0))))
                seq += 1
                time.sleep(0.05)
            warm = server.source.received  # at least these, and any in flight, moved nothing
            for walked in range(seq, seq + 200):  # the ball rolls about -y: the ant walks along the dome's +x
                pub.put(wire.encode(BallSample(0.0, walked, (0.0, -0.001, 0.0))))
            assert wait_for(lambda: server.loop.pose.x == pytest.approx(200 * 0.001 * 0.05), 5.0)
            assert server.status()["locomotion"]["received"] >= warm + 200
    finally:
        server.stop()


def test_a_server_starts_once_and_with_accepts_a_started_one(tmp_path):
    import threading

    from antarium.server.server import ServerError

    with Server(_config(tmp_path), renderer_factory=None, link=False).start_thread() as server:
        assert [t.name for t in threading.enumerate()].count("antarium-server tb") == 1
        with pytest.raises(ServerError, match="started already; a server starts once"):
            server.start_thread()
        assert wait_for(lambda: server.loop.frame > 0, 5.0)  # the one server runs
    assert not any(t.name == "antarium-server tb" for t in threading.enumerate())  # and its thread ended


def test_a_rig_without_renderer_publishes_render_time_as_nan_not_zero(tmp_path):
    """docs/bus.md: a stage that did not run is NaN; a pose-only rig renders nothing, so `render` is NaN."""
    config = _config(tmp_path, rig="tstats")
    server = Server(config, renderer_factory=None, link=False).start_thread()
    try:
        received = []
        with bus.open_session(config.bus, "client") as s:
            sub = s.declare_subscriber(bus.stats_key("tstats"),
                                       lambda sample: received.append(bus.decode_stats(sample.payload.to_bytes())))
            assert wait_for(lambda: len(received) >= 3, 10.0)
            sub.undeclare()
        assert all(math.isnan(r["render"]) and math.isnan(r["sample"]) for r in received), received[:3]
    finally:
        server.stop()


def test_a_second_server_for_the_same_rig_on_one_bus_is_refused(tmp_path):
    """Two servers named alike on one bus both ran every command (one set_pose moved both) and interleaved their
    poses on one stream; the second is refused at its start, naming the rig. Another name on the same bus runs."""
    from antarium.server import ServerError

    first = Server(_config(tmp_path, rig="twin"), renderer_factory=None, link=False).start_thread()
    try:
        linked = {"connect": first.config.bus.listen}  # a second computer's server on the same network
        twin = Server(_config(tmp_path / "b", rig="twin", **linked), renderer_factory=None, link=False)
        with pytest.raises(ServerError, match=r"another antarium server already serves rig 'twin' on this bus .*"
                                              r"give this rig another \[rig\] name"):
            twin.start_thread()
        assert first.loop.frame > 0 and first.status()["alarms"] == []  # the first goes on
        other = Server(_config(tmp_path / "c", rig="other", **linked), renderer_factory=None, link=False)
        other.start_thread()
        other.stop()
    finally:
        first.stop()
