"""Experiment scripts (examples/) and `antarium.client`'s helpers for them: the rig named by --config, options
checked before anything is written or connected, every refusal one line with exit status 2, a slow reply named as
such, help texts that show their defaults."""

import argparse
import importlib.util
import json
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

import antarium
from antarium import bus, client
from antarium.client import RigError, RigTimeout, add_script_arguments, script_rig
from antarium.config import load_config, resolve
from antarium.server import Server, ServerError

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"
SCRIPTS = sorted(p.stem for p in EXAMPLES.glob("*.py"))


def _load(name):
    spec = importlib.util.spec_from_file_location(f"script_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _toml(tmp_path, rig: str) -> Path:
    """A rig config on a free port (nothing listens there unless a test starts a server)."""
    path = tmp_path / "rig.toml"
    path.write_text(f'[rig]\nname = "{rig}"\n[bus]\nlisten = ["{bus.free_tcp_endpoint()}"]\n'
                    f'[log]\ndir = "{tmp_path / "logs"}"\n')
    return path


def _script_args(argv):
    parser = argparse.ArgumentParser()
    add_script_arguments(parser)
    return parser.parse_args(argv)


# -- 1: the rig is the config's ---------------------------------------------------------------------------
def test_the_rig_defaults_to_the_configs_rig_name(tmp_path):
    toml = _toml(tmp_path, "tclirig")
    server = Server(load_config(toml), renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    try:
        with script_rig(_script_args(["--config", str(toml), "--timeout", "10"])) as rig:
            assert rig.name == "tclirig" and "frames" in rig.status()
    finally:
        server.stop()
    assert client.script_rig_name(_script_args([])) == "rig1"  # the embedded default's
    assert client.script_rig_name(_script_args(["--config", str(toml), "--rig", "other"])) == "other"


def test_no_server_is_one_line_naming_the_configs_rig(tmp_path, capsys):
    toml = _toml(tmp_path, "tclinobody")
    code = client.run_script(_load("virtual_displacement").main,
                      ["--config", str(toml), "--timeout", "0.3", "--short", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert ": error: no antarium server for rig 'tclinobody' answered within 0.3 s" in err[0]
    assert not (tmp_path / "out").exists()  # made only once the rig answers


def test_a_misspelt_rig_name_is_told_with_the_rigs_that_answer(tmp_path):
    toml = _toml(tmp_path, "tclirealrig")
    server = Server(load_config(toml), renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    try:
        with pytest.raises(RigError) as err:
            antarium.Rig("tclirelarig", config=toml, timeout_s=0.3).connect()
    finally:
        server.stop()
    assert "no antarium server for rig 'tclirelarig' answered within 0.3 s" in str(err.value)
    assert "servers answering there: rig 'tclirealrig' (a misspelt name?)" in str(err.value)
    with pytest.raises(RigError, match="no other antarium server answered there either"):
        antarium.Rig("tclirelarig", config=toml, timeout_s=0.3).connect()


def _quick_server_toml(tmp_path, rig: str) -> tuple[Path, str]:
    """A rig config quick to serve here (virtual dome, small faces, a plain scene) and its bus endpoint."""
    toml = _toml(tmp_path, rig)
    toml.write_text(toml.read_text() + '[link]\ninterface = "virtual"\n[render]\nscene = "horizon"\n'
                                       "face_size_px = 64\n")
    return toml, load_config(toml).bus.listen[0]


def _hold(endpoint: str) -> socket.socket:
    """Another server's listener on the TCP `endpoint` ("tcp/HOST:PORT")."""
    host, _, port = endpoint.removeprefix("tcp/").rpartition(":")
    other = socket.socket()
    other.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    other.bind((host, int(port)))
    other.listen()
    return other


def test_start_server_on_a_bus_port_in_use_is_the_line_serve_prints(tmp_path, capsys):
    """--start-server checks the config as `antarium serve` does: one line naming [bus] listen, no zenoh dump,
    and no --out folder left behind."""
    toml, endpoint = _quick_server_toml(tmp_path, "tclibusy")
    out = tmp_path / "out"
    with _hold(endpoint):
        code = client.run_script(_load("proof_of_concept").main,
                                 ["--config", str(toml), "--start-server", "--short", "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert f": error: [bus] listen endpoint {endpoint} is in use (another antarium serve?)" in err[0]
    assert not out.exists()


def test_a_start_that_fails_has_closed_the_server_when_the_error_comes(tmp_path, monkeypatch):
    """The port taken between the check and the start: the ServerError comes once the server's thread has closed
    what it opened (the renderer and its shared memory), not while it still closes it."""
    toml, endpoint = _quick_server_toml(tmp_path, "tclirace")
    toml.write_text(toml.read_text().replace('scene = "horizon"', 'scene = "habitat"'))  # far layer: shared memory
    monkeypatch.setattr("antarium.server.config_check.port_in_use", lambda *args: False)  # free when checked
    with _hold(endpoint), pytest.raises(ServerError, match="cannot open the zenoh session"):
        with script_rig(_script_args(["--config", str(toml), "--start-server"])):
            pytest.fail("no rig without a server")
    assert not [t.name for t in threading.enumerate() if t.name == "antarium-server tclirace"]


@pytest.mark.parametrize("script", ["proof_of_concept", "open_loop_panoramas", "virtual_displacement"])
def test_a_missing_config_is_refused_before_the_out_folder_is_made(tmp_path, capsys, script):
    out = tmp_path / "out"
    code = client.run_script(_load(script).main, ["--config", str(tmp_path / "rig.tom"), "--start-server", "--short",
                                                  "--out", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "rig config" in err[0] and "rig.tom' not found" in err[0], err
    assert not out.exists()


# -- 2: a slow reply ------------------------------------------------------------------------------------------
def test_a_slow_reply_is_a_rig_error_naming_rig_command_and_timeout():
    config = resolve({"rig": {"name": "tclislow"}, "bus": {"listen": [bus.free_tcp_endpoint()]}})
    release = threading.Event()

    def on_query(query):  # a server that takes longer than the client waits
        release.wait(10.0)
        query.reply(query.key_expr, json.dumps({"ok": True, "result": {}}))

    session = bus.open_session(config.bus, role="server")
    entities = [session.declare_queryable(bus.rig_key("tclislow", "cmd", "*"), on_query),
                session.liveliness().declare_token(bus.alive_key("tclislow"))]
    try:
        with antarium.Rig("tclislow", config=config, timeout_s=0.5) as rig, pytest.raises(RigError) as info:
            rig.status()
    finally:
        release.set()
        for entity in entities:
            entity.undeclare()
        session.close()
    assert type(info.value) is RigTimeout  # a RigError that says the command may have run
    assert "no reply from rig 'tclislow' to status within 0.5 s" in str(info.value)
    assert "raise --timeout" in str(info.value) and str(info.value) != "Timeout"


def test_a_scene_load_waits_for_its_reply_longer_than_other_commands():
    """A scene load parses, builds and uploads a whole world: the client waits at least its command's `reply_s`
    (SCENE_REPLY_S) for it, while other commands keep the Rig's timeout. The README's script timed out on
    load_scene after the default 10 s on a busy machine."""
    from antarium.server.commands import COMMANDS, SCENE_REPLY_S

    config = resolve({"rig": {"name": "tclscene"}, "bus": {"listen": [bus.free_tcp_endpoint()]}})

    def on_query(query):  # a server that answers every command after 1.2 s
        time.sleep(1.2)
        query.reply(query.key_expr, json.dumps({"ok": True, "result": {"done": str(query.key_expr)}}))

    session = bus.open_session(config.bus, role="server")
    entities = [session.declare_queryable(bus.rig_key("tclscene", "cmd", "*"), on_query),
                session.liveliness().declare_token(bus.alive_key("tclscene"))]
    try:
        with antarium.Rig("tclscene", config=config, timeout_s=0.5) as rig:
            assert rig.load_scene("habitat") == {"done": bus.command_key("tclscene", "load_scene")}
            with pytest.raises(RigTimeout, match="to status within 0.5 s"):
                rig.status()
            assert rig.reply_s("load_scene") == SCENE_REPLY_S == COMMANDS["load_scene"].reply_s
            assert rig.reply_s("status") == 0.5
    finally:
        for entity in entities:
            entity.undeclare()
        session.close()


_SLOW_COMMAND = """
import dataclasses, sys, time
import antarium
from antarium import bus, client
from antarium.config import resolve
from antarium.server import Server, commands

# a command whose slow part (run beside the loop) is still running when the script ends
commands.COMMANDS["gains"] = dataclasses.replace(commands.COMMANDS["gains"], prepare=lambda server, p: time.sleep(2.0))
config = resolve({"rig": {"name": "tabort"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                  "locomotion": {"source": "scripted"}})
server = Server(config, renderer_factory=None, link=False).start_thread()
try:
    with antarium.Rig("tabort", config=config, timeout_s=0.5) as rig:
        rig.gains(translation=2.0)
except client.RigTimeout:
    print("timed out", flush=True)
finally:
    server.stop()
sys.exit(2)
"""


def test_a_script_that_ends_while_its_server_answers_a_command_exits_cleanly(tmp_path):
    """A script whose command timed out (its server still answering it in zenoh's thread) and that then stopped its
    in-process server was killed by SIGABRT at exit (status 134, 'Fatal Python error: Aborted'): the shutdown
    returned while the query's thread still ran Python. The shutdown now waits for the queries being answered."""
    proc = subprocess.run([sys.executable, "-c", _SLOW_COMMAND], capture_output=True, text=True, timeout=120,
                          cwd=tmp_path)  # its server makes its [log] dir, ./trials, there
    assert (proc.returncode, proc.stdout) == (2, "timed out\n"), proc.stderr[-2000:]


def test_a_rig_refuses_a_timeout_that_is_not_positive():
    for bad in (-1.0, 0, float("nan"), "10"):
        with pytest.raises(RigError, match="timeout_s must be a positive number of seconds"):
            antarium.Rig("tclitimeout", timeout_s=bad)


# -- 3: options checked first, one line ----------------------------------------------------------------------
@pytest.mark.parametrize("script, args, message", [
    ("open_loop_panoramas", ["--seconds", "-1"], "--seconds must be a positive number of seconds"),
    ("open_loop_panoramas", ["--panorama", "missing.png"], "--panorama missing.png: no such file"),
    ("proof_of_concept", ["--duration", "-1"], "--duration must be a positive number of seconds"),
    ("proof_of_concept", ["--window", "nan"], "--window must be a positive number of seconds"),
    ("proof_of_concept", ["--duration", "5", "--window", "10", "--timeout", "1"],
     "--duration 5 s must be at least 3 x --window (10 s)"),  # else no rotation at all, silently
    ("virtual_displacement", ["--timeout", "-1"], "--timeout must be a positive number of seconds (at most 86400), "
                                                  "got -1"),
    ("virtual_displacement", ["--to-x", "nan"], "--to-x must be a finite number, got nan"),
    ("virtual_displacement", ["--to-y", "inf"], "--to-y must be a finite number, got inf"),
    ("virtual_displacement", ["--before", "-2"], "--before must be a positive number of seconds"),
])
def test_rig_scripts_check_their_options_before_writing_or_connecting(tmp_path, capsys, script, args, message):
    toml = _toml(tmp_path, "tclinever")  # nothing listens: a script that connected first would say so instead
    out = tmp_path / "out"
    code = client.run_script(_load(script).main, ["--config", str(toml), "--out", str(out), *args])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and ": error: " in err[0] and message in err[0], err
    assert not out.exists()  # nothing generated, no trial log


@pytest.mark.parametrize("script, args, message", [
    ("ant_homing", ["--length", "-1"], "--length must be a finite number >= 0.1"),
    ("ant_homing", ["--threshold", "nan"], "--threshold must be a finite number, got nan"),
    ("ant_shuttle", ["--trips", "0"], "--trips must be a finite number >= 0.1"),
])
def test_ant_scripts_check_their_options_first(tmp_path, capsys, script, args, message):
    out = tmp_path / "out"
    assert client.run_script(_load(script).main, ["--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0] and not out.exists()


def test_a_script_run_as_a_program_prints_one_line_and_exits_2(tmp_path):
    done = subprocess.run([sys.executable, str(EXAMPLES / "virtual_displacement.py"), "--to-x", "nan",
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.strip() == "virtual_displacement.py: error: --to-x must be a finite number, got nan"


@pytest.mark.parametrize("script", SCRIPTS)
def test_every_script_enters_through_run_script(script):
    assert "sys.exit(run_script(main))" in (EXAMPLES / f"{script}.py").read_text()


class _Parsed(Exception):
    def __init__(self, parser):
        super().__init__()
        self.parser = parser


@pytest.mark.parametrize("script", SCRIPTS)
def test_help_shows_every_default_and_a_whole_description(script, monkeypatch):
    def capture(self, args=None, namespace=None):
        raise _Parsed(self)

    monkeypatch.setattr(argparse.ArgumentParser, "parse_args", capture)
    with pytest.raises(_Parsed) as info:
        _load(script).main([])
    parser = info.value.parser
    assert parser.description.rstrip().endswith(".") and parser.description == parser.description.strip()
    for action in parser._actions:
        if action.default in (None, False, [], argparse.SUPPRESS) or action.required:
            continue
        assert action.help and "default" in action.help, f"{script} {action.option_strings}: {action.help!r}"
    formatter = parser._get_formatter()
    for option in ("--out", "--seed", "--duration", "--seconds", "--to-x", "--to-y", "--timeout"):
        action = parser._option_string_actions.get(option)
        if action is not None and not action.required:  # the help as printed shows the value
            shown = f"{action.default:g}" if isinstance(action.default, float) else str(action.default)
            assert f"default {shown}" in formatter._expand_help(action), (script, option)


def test_a_script_is_refused_while_its_rig_records_another_trial(tmp_path, capsys):
    """A second script on a recording rig loaded its scene, switched the loop and reset the origin inside the
    running trial (an 'open-loop' trial ended with 4,465 of 13,622 frames in closed loop), and only then was its own
    trial refused: it is refused before it sends anything, and the trial goes on untouched."""
    toml, _ = _quick_server_toml(tmp_path, "tclibusytrial")
    server = Server(load_config(toml), renderer_factory=None, link=False, echo=lambda line: None).start_thread()
    try:
        server.trial_start("running", {})
        server.loop.set_closed_loop(False)
        code = client.run_script(_load("proof_of_concept").main,
                                 ["--config", str(toml), "--short", "--out", str(tmp_path / "out")])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        assert ("rig 'tclibusytrial' is recording trial 'running': this script would change its scene and loop; run "
                "it when that trial has ended (one script at a time on a rig)") in err[0]
        assert not server.loop.closed_loop and server.trial_name == "running"
        assert not (tmp_path / "out").exists()
    finally:
        server.stop()


def test_a_script_that_fails_before_writing_leaves_no_empty_out_folder(tmp_path, capsys):
    """open_loop_panoramas with an image OpenCV cannot decode: the first load is refused in one line, and the
    --out folder script_rig had made stayed behind, empty. A folder that existed before, or holds files, stays."""
    toml, _ = _quick_server_toml(tmp_path, "tcliemptyout")
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    server = Server(load_config(toml), echo=lambda line: None).start_thread()
    try:
        script = _load("open_loop_panoramas").main
        out = tmp_path / "out"
        code = client.run_script(script, ["--config", str(toml), "--short", "--panorama", str(bad), "--out", str(out)])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1 and "cannot decode image" in err[0], err
        assert not out.exists()
        kept = tmp_path / "kept"
        kept.mkdir()
        assert client.run_script(script, ["--config", str(toml), "--short", "--panorama", str(bad),
                                          "--out", str(kept)]) == 2
        assert kept.is_dir()
    finally:
        server.stop()
