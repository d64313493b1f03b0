"""The experiment scripts' view of the rig (antarium.Rig against a real pose-only server): two scripts' trials, a
command the bus refuses, and the Rig's own timeout."""

from pathlib import Path

import pytest
from test_bus_acl import LAB, OPERATORS, doc_acl, serve

import antarium
from antarium import bus
from antarium.client import WAIT_MAX_S, RigError, RigTimeout
from antarium.config import resolve
from antarium.server import Server


def test_a_scripts_trial_block_never_stops_another_scripts_trial(tmp_path):
    """Script B stops script A's trial and starts its own; A's `with rig.trial` end stops nothing of B's and says
    so (before: it stopped B's trial without a word)."""
    config = resolve({"rig": {"name": "rigreview"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "log": {"dir": str(tmp_path / "logs")}, "locomotion": {"source": "scripted", "speed": 0.0}})
    server = Server(config, renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    try:
        with antarium.Rig("rigreview", config=config) as a, antarium.Rig("rigreview", config=config) as b:
            with pytest.raises(RigError, match=r"trial_stop: the trial of log .*_a\.h5' is not running .*the running "
                                               r"trial 'b' .* was not stopped"):
                with a.trial("a") as path_a:
                    assert b.stop_trial()["path"] == path_a
                    path_b = b.start_trial("b")
            assert server.trial_name == "b"
            with pytest.raises(RigError, match="is not running"):
                a.stop_trial(path_a)
            assert server.trial_name == "b"
            assert b.stop_trial(Path(path_b))["path"] == path_b  # a Path as start_trial gave it
            assert server.trial_name is None
    finally:
        server.stop()


def test_a_command_the_access_control_refuses_is_said_as_such_at_once(tmp_path):
    """A lab peer's command ends with no reply at once: a RigError (not a RigTimeout) saying after how long the bus
    ended the query, not that it waited `timeout_s`."""
    acl = doc_acl().replace(OPERATORS, OPERATORS.replace('"lo", ', ""))
    config, server = serve(tmp_path, acl.replace(LAB, LAB.replace('"eth0"', '"eth0", "lo"')))
    try:
        with antarium.Rig("rig1", config=config, timeout_s=30.0) as rig:
            with pytest.raises(RigError, match=r"rotate_scene: no reply from rig 'rig1': the bus ended the query "
                                               r"after \d+\.\d s \(of 30 s\) without one: refused by the bus's access "
                                               r"control") as info:
                rig.rotate_scene(45)
            assert not isinstance(info.value, RigTimeout) and "within 30 s" not in str(info.value)
        assert server.loop.scene_rotation == 0.0
    finally:
        server.stop()


@pytest.mark.parametrize("timeout_s", [1e30, WAIT_MAX_S * 2])
def test_a_timeout_beyond_a_day_is_one_rig_error(timeout_s):
    """A timeout longer than threading's and zenoh's waits can take was an OverflowError from connect()."""
    with pytest.raises(RigError, match=r"timeout_s must be a positive number of seconds \(at most 86400\)"):
        antarium.Rig("rig1", timeout_s=timeout_s)


def test_a_peer_the_access_control_refuses_is_not_told_that_no_server_runs(tmp_path):
    """Refused everything (the doc's file, `lo` in no subject), a Rig reaches the server's session but sees no token:
    it says so and names the access control (before: 'no other antarium server answered there either')."""
    config, server = serve(tmp_path, doc_acl().replace(OPERATORS, OPERATORS.replace('"lo", ', "")))
    try:
        zid = str(server.session.info.zid())
        with pytest.raises(RigError, match=rf"no antarium server for rig 'rig1' answered within 1.0 s .* this "
                                           rf"computer reached the zenoh session\(s\) {zid} there, which shows no "
                                           r"antarium server: the server is not running, or its bus access control "
                                           r"\(\[bus\] access_control\) refuses this computer$"):
            antarium.Rig("rig1", config=config, timeout_s=1.0).connect()
    finally:
        server.stop()



def test_a_slow_command_of_one_script_does_not_hold_up_another_scripts_commands(tmp_path, monkeypatch):
    """zenoh answers a queryable's queries one after another: while script A's scene load prepared (seconds), script
    B's status() waited for it (8 s seen), or timed out. Slow commands are answered on a worker of their own: here
    B's status and gains are answered while A's slow command is held, and A's is answered once released."""
    import dataclasses
    import threading

    from antarium.server import commands

    release = threading.Event()
    held = threading.Event()

    def prepare(server, p):
        held.set()
        release.wait(60)

    monkeypatch.setitem(commands.COMMANDS, "set_pose", dataclasses.replace(commands.COMMANDS["set_pose"],
                                                                           prepare=prepare))
    config = resolve({"rig": {"name": "rigslow"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "log": {"dir": str(tmp_path / "logs")}, "locomotion": {"source": "scripted", "speed": 0.0}})
    server = Server(config, renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    replies = {}
    try:
        with antarium.Rig("rigslow", config=config) as a, antarium.Rig("rigslow", config=config, timeout_s=5) as b:
            slow = threading.Thread(target=lambda: replies.setdefault("a", a.call("set_pose", x=0.5, y=0.0)))
            slow.start()
            assert held.wait(30)
            assert "frames" in b.status() and b.call("gains", rotation=2.0)["gains"]["rotation"] == 2.0
            assert not release.is_set() and "a" not in replies  # answered while A's command was held
            release.set()
            slow.join(30)
            assert replies["a"]["pose"]["x"] == pytest.approx(0.5)
    finally:
        release.set()
        server.stop()
