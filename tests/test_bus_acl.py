"""The access-control example of docs/bus.md, loaded as written, enforced by a real server over loopback TCP.

Loopback is the only interface a test may use, so the doc's file is run three ways: as written (`lo` is an
operators' interface: a local script commands the rig), with `lo` moved to the doc's "lab" subject (the peer
watches the pose stream but its commands are refused) and with `lo` in no subject (an unlisted interface:
refused everything). Every variant is the doc's text with one substitution, checked to apply exactly once.
"""

import math
import re
import threading
import time
from pathlib import Path

import pytest
from conftest import wait_for

import antarium
from antarium import bus
from antarium.client import RigError
from antarium.config import resolve
from antarium.locomotion import BallSample, wire
from antarium.server import Server

DOC = (Path(__file__).resolve().parent.parent / "docs" / "bus.md").read_text()
OPERATORS = '{ id: "operators", interfaces: ["lo", "eth1"] }'
LAB = '{ id: "lab", interfaces: ["eth0"] }'


def doc_acl() -> str:
    security = DOC[DOC.index("## Security"):]
    match = re.search(r"```json5\n(.*?)```", security, re.S)
    assert match, "docs/bus.md: no json5 block under '## Security'"
    text = match.group(1)
    assert text.count(OPERATORS) == 1 and text.count(LAB) == 1, "the doc's subjects changed: update this test"
    return text


def serve(tmp_path, acl_text: str, locomotion: dict | None = None):
    acl = tmp_path / "acl.json5"
    acl.write_text(acl_text)
    config = resolve({
        "rig": {"name": "rig1"},  # the doc's key expressions name rig1
        "bus": {"listen": [bus.free_tcp_endpoint()], "access_control": str(acl)},
        "log": {"dir": str(tmp_path / "logs")},
        "locomotion": locomotion or {"source": "scripted", "speed": 0.02},
    })
    return config, Server(config, renderer_factory=None, link=False).start_thread()


def refused_command(server, session) -> None:
    """A raw query for a command gets no reply at all, and the rig is unchanged."""
    before = server.loop.scene_rotation
    replies = list(session.get(bus.command_key("rig1", "rotate_scene"), payload=b'{"deg": 45}', timeout=1.0))
    assert replies == []
    assert server.loop.scene_rotation == before


def test_the_documented_acl_lets_a_loopback_script_command_the_rig(tmp_path):
    config, server = serve(tmp_path, doc_acl())
    try:
        with antarium.Rig("rig1", config=config, timeout_s=5.0) as rig:
            assert rig.rotate_scene(45)["scene_rotation_deg"] == pytest.approx(45)
            assert rig.closed_loop(False)["closed_loop"] is False
            assert rig.status()["rig"] == "rig1"
        assert math.degrees(server.loop.scene_rotation) == pytest.approx(45)
    finally:
        server.stop()


def test_a_peer_on_a_lab_interface_watches_and_sends_locomotion_but_cannot_command(tmp_path):
    acl = doc_acl().replace(OPERATORS, OPERATORS.replace('"lo", ', ""))
    acl = acl.replace(LAB, LAB.replace('"eth0"', '"eth0", "lo"'))
    config, server = serve(tmp_path, acl, locomotion={"source": "bus", "timeout_s": 5.0})
    try:
        with bus.open_session(config.bus, role="client") as session:
            got_pose = threading.Event()
            poses = []

            def on_pose(sample):
                poses.append(bus.decode_pose(bytes(sample.payload.to_bytes())))
                got_pose.set()

            subscriber = session.declare_subscriber(bus.pose_key("rig1"), on_pose)
            assert got_pose.wait(5.0), "the lab may watch the pose stream"
            subscriber.undeclare()
            assert poses[0]["closed_loop"] is True
            publisher = bus.locomotion_publisher(session, "rig1")  # a trackball PC on the lab network
            for seq in range(50):
                publisher.put(wire.encode(BallSample(0.0, seq, (0.0, -0.001, 0.0))))
            assert wait_for(lambda: server.source.received == 50, 5.0)
            # the server takes the lab's puts on the locomotion key, and refuses them on any other key of the rig's
            # (subscribers in the server's own session, where the access control is enforced, tell)
            heard = {"locomotion": threading.Event(), "other": threading.Event()}
            subscribers = [
                server.session.declare_subscriber(bus.locomotion_key("rig1"), lambda s: heard["locomotion"].set()),
                server.session.declare_subscriber(bus.rig_key("rig1", "fake"), lambda s: heard["other"].set())]
            time.sleep(0.5)  # declarations reach the lab peer
            session.put(bus.rig_key("rig1", "fake"), b"not allowed")
            publisher.put(wire.encode(BallSample(0.0, 50, (0.0, -0.001, 0.0))))
            assert heard["locomotion"].wait(5.0)
            assert not heard["other"].wait(1.0), "a lab peer's put on another key is refused"
            for subscriber in subscribers:
                subscriber.undeclare()
            refused_command(server, session)
            with antarium.Rig("rig1", config=config, session=session, timeout_s=1.0) as rig:  # sees the server
                with pytest.raises(RigError, match="refused by the bus's access control"):
                    rig.rotate_scene(45)
            assert server.loop.scene_rotation == 0.0
    finally:
        server.stop()


def test_a_peer_on_an_unlisted_interface_is_refused(tmp_path):
    acl = doc_acl().replace(OPERATORS, OPERATORS.replace('"lo", ', ""))
    assert '"lo"' not in acl
    config, server = serve(tmp_path, acl)
    try:
        with bus.open_session(config.bus, role="client") as session:
            with pytest.raises(RigError, match="no antarium server"):  # it cannot even see the server
                antarium.Rig("rig1", config=config, session=session, timeout_s=1.0).connect()
            refused_command(server, session)
            status = list(session.get(bus.command_key("rig1", "status"), timeout=1.0))
            assert status == []
    finally:
        server.stop()



@pytest.mark.parametrize(("text", "message"), [
    ('{ enabled: "yes", default_permission: "deny" }', r"line 1, column 12: invalid type: string \"yes\", expected a "
                                                       "boolean$"),
    ('{\n  enabled: true,\n  default_permission: "maybe",\n}', "line 3, column 23: unknown variant `maybe`"),
    ('{ enabled: true, default_permission: "deny" } }', "line 1, column 47: expected EOI$"),
])
def test_a_broken_acl_file_is_one_line_naming_its_own_line_and_column(tmp_path, text, message):
    """Positions are those of the file (not of a text wrapped around it) and zenoh's Rust source paths are gone."""
    acl = tmp_path / "acl.json5"
    acl.write_text(text)
    with pytest.raises(ValueError, match="access_control file .*is not a valid zenoh ACL: " + message) as info:
        bus.session_config({"access_control": str(acl)}, role="server")
    assert "\n" not in str(info.value) and ".rs:" not in str(info.value)


def test_an_acl_zenoh_refuses_at_open_is_one_line_without_rust_source_paths(tmp_path):
    acl = tmp_path / "acl.json5"
    acl.write_text('{ enabled: true, default_permission: "deny", rules: [{ id: "r", permission: "allow", '
                   'flows: ["ingress"], messages: ["put"], key_exprs: ["antarium/rig1/**"] }], subjects: '
                   '[{ id: "s", interfaces: ["lo"] }], policies: [{ rules: ["nosuch"], subjects: ["s"] }] }')
    with pytest.raises(RuntimeError, match="Rule 'nosuch' in policy #0 does not exist in rules list$") as info:
        bus.open_session({"listen": [bus.free_tcp_endpoint()], "access_control": str(acl)}, role="server")
    assert ".rs:" not in str(info.value)


def test_an_acl_naming_an_interface_this_computer_lacks_is_said_at_start(tmp_path):
    """A subject's interface that does not exist here (misspelt, a card not plugged in) matches no connection: the
    server says so in one line at start, naming the subject, the interface and the interfaces it has; the doc's
    example as written says nothing of an interface this computer has."""
    import socket

    have = {name for _, name in socket.if_nameindex()}
    acl = tmp_path / "acl.json5"
    acl.write_text(doc_acl().replace(OPERATORS, '{ id: "operators", interfaces: ["lo", "enp9s9x"] }'))
    lines = bus.acl_missing_interfaces(acl)
    assert lines[0].startswith("[bus] access_control subject 'operators' names the network interface 'enp9s9x', "
                               "which this computer does not have (it has ")
    assert "lo" in lines[0] and all("'lo'" not in line for line in lines)
    assert len(lines) == 1 + ("eth0" not in have)  # the doc's lab subject names eth0

    echoed = []
    config = resolve({"rig": {"name": "rig1"}, "log": {"dir": str(tmp_path / "logs")},
                      "bus": {"listen": [bus.free_tcp_endpoint()], "access_control": str(acl)}})
    server = Server(config, renderer_factory=None, link=False, echo=echoed.append).start_thread()
    try:
        assert [line for line in echoed if "access_control" in line] == [f"antarium serve: {line}" for line in lines]
    finally:
        server.stop()
