"""The bus helpers: key names, sessions from the [bus] section over loopback, stream structs."""

import json
import time

import pytest

from antarium import bus
from antarium.core.pose import Pose
from antarium.locomotion import BallSample, wire


def test_keys_share_the_rig_prefix():
    assert bus.locomotion_key("rig1") == "antarium/rig1/locomotion"
    assert bus.command_key("rig1", "set_pose") == "antarium/rig1/cmd/set_pose"
    assert bus.alive_key("r") == "antarium/r/alive/server"
    with pytest.raises(ValueError, match="key chunk"):
        bus.command_key("rig1", "cmd/fly")


@pytest.mark.parametrize("name", ["@rig", "rig\x00", "tab\there", "a/b", "r*", ""])
def test_a_rig_name_that_wildcards_would_not_match_is_refused(name):
    """zenoh reads a chunk starting with '@' verbatim: `antarium/**` (access rules, monitors) would not match it."""
    with pytest.raises(ValueError, match="rig name must be a non-empty key chunk without"):
        bus.check_rig_name(name)


def test_a_bus_message_that_is_not_a_json_object_is_skipped():
    assert bus.json_object(b'{"kind": "x", "data": {}}') == {"kind": "x", "data": {}}
    for payload in (b"\xff\xfe", b"{not json", b"[1, 2]", b'"text"', b"3"):
        assert bus.json_object(payload) is None


def test_malformed_events_never_reach_a_scripts_callback(tmp_path):
    from antarium.client import Rig
    from antarium.config import resolve
    from antarium.server import Server

    config = resolve({"rig": {"name": "tev"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "log": {"dir": str(tmp_path / "trials")}})
    server = Server(config, renderer_factory=None, link=False).start_thread()
    got = []
    try:
        with Rig("tev", config=config, timeout_s=10.0) as rig:
            rig.on_event(got.append)
            deadline = time.monotonic() + 10
            while sum(e == {"kind": "forged"} for e in got) < 3 and time.monotonic() < deadline:  # surely reached
                for payload in (b"\xff", b"[1, 2]", b"{bad", json.dumps({"kind": "forged"}).encode()):
                    rig.session.put(bus.events_key("tev"), payload)
                time.sleep(0.05)
    finally:
        server.stop()
    assert sum(e == {"kind": "forged"} for e in got) >= 3 and all(isinstance(e, dict) for e in got)


def test_an_unknown_command_is_a_rig_error_before_anything_is_sent():
    from antarium.client import Rig, RigError

    with pytest.raises(RigError, match="unknown command 'fly'; allowed: load_scene, set_pose"):
        Rig("rig1").call("fly")
    with pytest.raises(ValueError, match="rig name"):
        bus.rig_key("a/b")


def test_client_config_listens_nowhere_and_connects_to_server_endpoint():
    section = {"listen": ["tcp/127.0.0.1:9"], "connect": []}
    conf = bus.session_config(section, role="client")
    assert json.loads(conf.get_json("listen/endpoints")) == []
    assert json.loads(conf.get_json("connect/endpoints")) == ["tcp/127.0.0.1:9"]
    assert json.loads(conf.get_json("scouting/multicast/enabled")) is False
    server = bus.session_config(section, role="server")
    assert json.loads(server.get_json("listen/endpoints")) == ["tcp/127.0.0.1:9"]
    assert json.loads(server.get_json("mode")) == "peer"


def test_locomotion_sample_travels_from_client_to_server():
    import zenoh

    section = {"listen": [bus.free_tcp_endpoint()]}
    with bus.open_session(section, "server") as server, bus.open_session(section, "client") as client:
        sub = server.declare_subscriber(bus.locomotion_key("t1"), zenoh.handlers.RingChannel(16))
        pub = client.declare_publisher(bus.locomotion_key("t1"), express=True)
        sample = BallSample(0.0, 7, (0.1, -0.2, 0.3), 12.5, 0.9)
        received = None
        deadline = time.monotonic() + 5.0
        while received is None and time.monotonic() < deadline:
            pub.put(wire.encode(sample))
            time.sleep(0.02)
            received = sub.try_recv()
        assert received is not None
        got = wire.decode(received.payload.to_bytes(), t=1.0)
        assert got.seq == 7 and got.rotation == (0.1, -0.2, 0.3) and got.t_device == 12.5


def test_pose_and_stats_structs_round_trip():
    payload = bus.encode_pose(5, 1.5, Pose(1.0, 2.0, 0.01, 0.5), 1.25, True, False)
    assert len(payload) == 56
    d = bus.decode_pose(payload)
    assert (d["frame"], d["x"], d["heading"], d["scene_rotation"], d["closed_loop"], d["fixed_tether"]) == (
        5, 1.0, 0.5, 1.25, True, False)
    s = bus.decode_stats(bus.encode_stats(3, 1, 2.0, 0.001, 0.002, 0.0, 0.0005, 0.0003, 1e-5))
    assert s["late_frames"] == 1 and s["render"] == 0.002
    with pytest.raises(bus.StreamError, match="56 bytes"):
        bus.decode_pose(payload[:-1])
    with pytest.raises(bus.StreamError, match="version 9"):
        bus.decode_pose(bytes([9]) + payload[1:])



@pytest.mark.parametrize(("stream", "offset", "value", "message"), [
    ("pose", 1, 0x04, "flags 0x07 set bits this version does not define"),   # bit 2: a later version's flag
    ("pose", 2, 0x01, "reserved fields must be 0"),
    ("stats", 1, 0x01, "reserved fields must be 0"),
    ("stats", 12, 0x01, "reserved fields must be 0"),
])
def test_pose_and_stats_payloads_of_a_later_version_are_refused_not_misread(stream, offset, value, message):
    """Reserved bytes and undefined flags were ignored until 2026-11-27 (the locomotion struct refused them)."""
    payload = bytearray(bus.encode_pose(5, 1.5, Pose(1.0, 2.0, 0.01, 0.5), 1.25, True, True) if stream == "pose"
                        else bus.encode_stats(3, 1, 2.0, 0.001, 0.002, 0.0, 0.0005, 0.0003, 1e-5))
    payload[offset] |= value
    with pytest.raises(bus.StreamError, match=f"^{stream} payload {message}"):
        (bus.decode_pose if stream == "pose" else bus.decode_stats)(bytes(payload))
