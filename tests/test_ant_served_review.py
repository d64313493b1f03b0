"""The served virtual ant when its server goes away mid-run: it says so at once (not after its pose timeout) and
keeps what it had done (served.json: the decisions so far, why it stopped, the trial log)."""

import json
import math
import threading

import pytest
from conftest import wait_for
from test_ant_served import ROUTE, _config, model_file  # noqa: F401  (the module's trained-ant fixture)

from antarium.ant.served import run_served, served_config
from antarium.client import RigError
from antarium.server import Server


def test_a_server_stopped_mid_run_ends_the_ant_at_once_and_keeps_its_decisions(model_file, tmp_path):  # noqa: F811
    config = _config(tmp_path)
    server = Server(served_config(config), echo=lambda line: None).start_thread()

    def stop_mid_run() -> None:
        """Stop the server once the ant, released at the route's start, has walked 3 cm of it (some decisions)."""
        def walked() -> float:
            return math.hypot(server.loop.pose.x - ROUTE.start[0], server.loop.pose.y - ROUTE.start[1])

        if wait_for(lambda: server.trial_log is not None and walked() < 0.01, 60.0):
            wait_for(lambda: walked() > 0.03, 60.0)
        server.stop()

    stopper = threading.Thread(target=stop_mid_run)
    stopper.start()
    try:
        with pytest.raises(RigError, match="is gone") as raised:
            run_served(model_file, config, tmp_path / "out", max_decisions=100_000, echo=lambda line: None)
        # the ant's wait for the next pose ended on the server's going (not on its pose timeout): that error is the
        # one raised, not the failed stop of the trial that follows it
        assert str(raised.value).startswith("pose: ")
    finally:
        stopper.join()
        server.stop()
    kept = json.loads((tmp_path / "out" / "served.json").read_text())
    assert "is gone" in kept["summary"]["stopped"]
    assert kept["summary"]["trial_log"].endswith("_virtual_ant.h5")
    decisions = [e for e in kept["events"] if e["kind"] == "ant_decision"]
    assert decisions and all({"x", "y", "heading", "frame"} <= set(e) for e in decisions)


def test_a_rig_that_never_answers_leaves_no_output_folder(model_file, tmp_path, capsys):  # noqa: F811
    """Nothing served (the config's rig has no server): one RigError after `timeout_s`, and no `out` made."""
    with pytest.raises(RigError, match="no antarium server for rig 'antserved' answered within 0.3 s"):
        run_served(model_file, _config(tmp_path), tmp_path / "out", echo=lambda line: None, timeout_s=0.3)
    assert not (tmp_path / "out").exists()
    from antarium.cli import main

    assert main(["ant", "serve", str(model_file), "--config", "rig.toml", "--out", str(tmp_path / "cli"),
                 "--timeout", "0"]) == 2
    assert "--timeout must be > 0 s" in capsys.readouterr().err
    for option in ("--lateral-cm", "--heading-deg"):
        assert main(["ant", "serve", str(model_file), "--config", "rig.toml", "--out", str(tmp_path / "cli"),
                     option, "nan"]) == 2
        assert f"{option} must be a finite number" in capsys.readouterr().err
    assert not (tmp_path / "cli").exists()


def test_the_dome_settles_when_its_first_hello_is_lost():
    """The dome's socket dropped the settle's HELLO (overflowing with a loaded server's frames): settle sends it
    again until answered instead of waiting out its whole timeout."""
    from antarium.ant.served import DomeHost
    from antarium.firmware_proto.control import encode_hello
    from antarium.server.emulator_process import free_udp_port

    dome = DomeHost("127.0.0.1", free_udp_port("127.0.0.1"))
    handle, dropped = dome.handle_datagram, []

    def lose_the_first_hello(payload):
        if not dropped and bytes(payload) == encode_hello(dome._tag):
            dropped.append(payload)
            return []
        return handle(payload)

    dome.handle_datagram = lose_the_first_hello
    dome.start()
    try:
        dome.settle(3.0)
    finally:
        dome.stop()
    assert len(dropped) == 1
