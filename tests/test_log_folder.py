"""Where trial logs go (issue #20, point 11): the paths reported to scripts are absolute, and a script's trials
log into the output folder it names."""

from pathlib import Path

import pytest

from antarium import bus
from antarium.client import Rig, RigError
from antarium.config import resolve
from antarium.server import Server
from antarium.trial_log import check_log_dir


def test_a_relative_log_dir_becomes_absolute(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert check_log_dir("trials") == tmp_path.resolve() / "trials"
    assert (tmp_path / "trials").is_dir()


@pytest.fixture
def served(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # the server's working folder: a relative [log] dir lands here
    config = resolve({"rig": {"name": "tfolder"}, "bus": {"listen": [bus.free_tcp_endpoint()]},
                      "log": {"dir": "trials", "flush_s": 0.1}, "render": {"scene": "horizon", "face_size_px": 64},
                      "link": {"interface": "virtual"}, "loop": {"rate_hz": 100.0}})
    server = Server(config, echo=lambda line: None).start_thread()
    yield config, tmp_path.resolve()
    server.stop()


def test_trial_paths_are_absolute_and_under_the_folder_the_script_names(served):
    config, here = served
    with Rig("tfolder", config=config) as rig, rig.trial("default") as path:
        assert Path(path).is_absolute() and Path(path).parent == here / "trials"
    with Rig("tfolder", config=config, log_dir="run1") as rig, rig.trial("mine") as path:
        assert Path(path).parent == here / "run1"
    assert Path(path).stat().st_size > 0
    with Rig("tfolder", config=config) as rig:
        with pytest.raises(RigError, match="trial_start: parameter 'folder' must be an absolute path, got 'run2'"):
            rig.call("trial_start", name="bad", folder="run2")
    assert not (here / "run2").exists()


def test_commands_report_absolute_paths(tmp_path, monkeypatch, capsys):
    from antarium.cli import main

    monkeypatch.chdir(tmp_path)
    assert main(["layout", "--out", "pictures"]) == 0
    pictures = [line.split(": ", 1)[1] for line in capsys.readouterr().out.splitlines() if line.startswith("picture:")]
    assert pictures == [str(tmp_path.resolve() / "pictures" / n) for n in ("layout_mollweide.png", "layout_3d.png")]
    Path("route.csv").write_text("x_m,y_m\n0.5,-0.3\n0.7,-0.28\n")
    assert main(["ant", "learn", "--route", "route.csv", "--spacing", "0.05", "--out", "ant.npz"]) == 0
    assert f"wrote {tmp_path.resolve() / 'ant.npz'}" in capsys.readouterr().out
