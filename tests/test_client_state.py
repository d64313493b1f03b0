"""antarium.Rig's own state: a closed or orphaned Rig does not pretend to be connected, a timeout says the command
may have run, a bad rig name is a RigError."""

import pytest
from conftest import wait_for

import antarium
from antarium import bus
from antarium.client import RigError, RigTimeout
from antarium.config import resolve
from antarium.server import Server


def _served(tmp_path, rig):
    config = resolve({"rig": {"name": rig}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "log": {"dir": str(tmp_path)}, "locomotion": {"source": "scripted", "speed": 0.02}})
    return config, Server(config, renderer_factory=None, link=False).start_thread()


def test_a_closed_rig_has_no_pose_and_does_not_reconnect_to_a_stopped_server(tmp_path):
    config, server = _served(tmp_path, "tclose")
    rig = antarium.Rig("tclose", config=config, timeout_s=3.0).connect()
    try:
        assert wait_for(lambda: rig.latest() is not None, 5.0)
        rig.close()
        assert rig.latest() is None
        with pytest.raises(RigError, match="not connected"):
            rig.pose()
    finally:
        server.stop()
    rig.timeout_s = 1.0
    with pytest.raises(RigError, match="no antarium server for rig 'tclose' answered"):
        rig.connect()  # it returned at once: the old liveliness was kept


def test_a_rig_whose_server_stopped_forgets_its_last_pose(tmp_path):
    config, server = _served(tmp_path, "tgone")
    rig = antarium.Rig("tgone", config=config, timeout_s=3.0).connect()
    try:
        assert wait_for(lambda: rig.latest() is not None, 5.0)
        server.stop()
        assert wait_for(lambda: rig.latest() is None, 10.0)
    finally:
        rig.close()


def test_a_reply_that_comes_too_late_is_a_timeout_that_may_have_run(tmp_path):
    """The command ran (the pose moved) though the Rig gave up waiting: RigTimeout says so, unlike a refusal."""
    import time

    config, server = _served(tmp_path, "tlate")
    run = server.command

    def slow(name, params=None):  # a server busy for 0.5 s (a scene load) before it runs the command
        time.sleep(0.5)
        return run(name, params)

    server.command = slow
    rig = antarium.Rig("tlate", config=config, timeout_s=0.1).connect()
    try:
        with pytest.raises(RigTimeout, match="may still have run it: check status"):
            rig.set_pose(7.0, 7.0)
        rig.timeout_s = 5.0
        assert wait_for(lambda: abs(rig.status()["pose"]["x"] - 7.0) < 0.1, 5.0)  # moved there (and walks on)
    finally:
        rig.close()
        server.stop()


def test_a_bad_rig_name_is_a_rig_error():
    with pytest.raises(RigError, match="rig name"):
        antarium.Rig("a/b")


def test_ctrl_c_in_a_trial_block_stops_the_trial_and_names_its_kept_log(tmp_path, capsys):
    """A script interrupted inside `with rig.trial(...)`: the trial is stopped, and stderr names the closed log
    and its frames, so the experimenter knows what was kept."""
    import h5py

    config, server = _served(tmp_path, "tintr")
    rig = antarium.Rig("tintr", config=config, timeout_s=5.0).connect()
    try:
        with pytest.raises(KeyboardInterrupt), rig.trial("walk", ant=3) as path:
            assert wait_for(lambda: rig.status()["log"]["rows_written"].get("frames", 0) >= 5, 10.0)
            raise KeyboardInterrupt
        assert rig.status()["trial"] is None
    finally:
        rig.close()
        server.stop()
    err = capsys.readouterr().err
    assert f"trial 'walk' stopped by the interruption: its log {path} is closed and kept (" in err
    frames = int(err.split("is closed and kept (")[1].split(" frames)")[0])
    with h5py.File(path, "r") as f:
        assert frames >= 5 and len(f["frames"]) == frames
        assert f["events"]["kind"][-1].decode() == "trial_stopped"


def test_an_error_in_a_trial_block_is_the_one_raised_when_the_stop_fails_too(tmp_path, capsys):
    """The server gone inside `with rig.trial(...)`: the trial's stop failed too, and its RigError replaced the
    block's own error (a served ant saw 'trial_stop: ... is gone' instead of why its walk ended)."""
    config, server = _served(tmp_path, "tmask")
    rig = antarium.Rig("tmask", config=config, timeout_s=3.0).connect()
    try:
        with pytest.raises(ValueError, match="the block's own error"), rig.trial("walk"):
            server.stop()
            assert wait_for(lambda: rig.latest() is None, 10.0)  # the Rig knows its server is gone
            raise ValueError("the block's own error")
    finally:
        rig.close()
        server.stop()
    err = capsys.readouterr().err
    assert "trial 'walk' was not stopped (" in err and "the error in its block follows" in err
