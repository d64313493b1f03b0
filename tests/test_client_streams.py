"""antarium.Rig's subscriptions and its view of the server over time: a server that goes away is told and a
command to it fails at once, a server that comes back is told as a new run, a callback that is not a function is
refused and one that raises is told once (not once per pose), and `connect=` endpoints are checked as the
config's are."""

import time

import pytest
from conftest import wait_for

import antarium
from antarium import bus
from antarium.client import RigError, RigTimeout
from antarium.config import resolve
from antarium.server import Server


def _config(tmp_path, rig, endpoint):
    return resolve({"rig": {"name": rig}, "bus": {"listen": [endpoint]}, "log": {"dir": str(tmp_path)},
                    "locomotion": {"source": "scripted", "speed": 0.02}})


def _serve(config):
    return Server(config, renderer_factory=None, link=False).start_thread()


def test_a_command_to_a_gone_server_fails_at_once_and_a_server_back_is_told(tmp_path, capsys):
    config = _config(tmp_path, "tback", bus.free_tcp_endpoint())
    server = _serve(config)
    rig = antarium.Rig("tback", config=config, timeout_s=5.0).connect()
    try:
        assert wait_for(lambda: rig.latest() is not None, 5.0)
        server.stop()
        assert wait_for(lambda: rig.latest() is None, 10.0)
        start = time.monotonic()
        with pytest.raises(RigError, match="the server of rig 'tback' is gone .*the command was not sent") as info:
            rig.status()
        assert not isinstance(info.value, RigTimeout)  # not "it may have run": nobody was there to run it
        with pytest.raises(RigError, match="pose: the server of rig 'tback' is gone .*there is no pose"):
            rig.pose()
        assert time.monotonic() - start < 1.0  # not the whole timeout_s
        server = _serve(config)  # the same endpoint: the Rig's session connects again by itself
        assert wait_for(lambda: rig.latest() is not None, 20.0)
        assert rig.status()["frames"] >= 0  # commands go through again
    finally:
        rig.close()
        server.stop()
    told = [line for line in capsys.readouterr().err.splitlines() if line.startswith("antarium.Rig:")]
    assert len(told) == 2 and "is gone" in told[0] and "is back: a new run" in told[1], told


def test_stream_callbacks_that_are_not_functions_are_refused_and_one_that_raises_is_told_once(tmp_path, capsys):
    config = _config(tmp_path, "tcall", bus.free_tcp_endpoint())
    server = _serve(config)
    calls = []

    def broken(update):
        calls.append(update.frame)
        raise ZeroDivisionError("the script's own bug")

    try:
        with antarium.Rig("tcall", config=config, timeout_s=5.0) as rig:
            for subscribe in (rig.on_pose, rig.on_event):
                for callback in (None, 42, "print"):
                    with pytest.raises(RigError, match="needs a function to call with each message"):
                        subscribe(callback)
            rig.on_pose(broken)
            assert wait_for(lambda: len(calls) >= 20, 10.0)
            assert rig.status()["frames"] > 0
    finally:
        server.stop()
    err = capsys.readouterr().err
    assert err.count("on_pose callback") == 1 and err.count("ZeroDivisionError: the script's own bug") == 1, err


@pytest.mark.parametrize(("connect", "message"), [
    ("tcp/127.0.0.1:7447", "connect must be a list of endpoints"),
    (["nonsense"], "connect: .*'nonsense' is not a zenoh endpoint"),
    ([7447], "connect: "),
])
def test_connect_endpoints_are_checked_before_anything_is_opened(connect, message):
    with pytest.raises(RigError, match=message):
        antarium.Rig("rig1", connect=connect)

