"""`antarium ant learn | run | evaluate`: files written, bad input refused with a clear error (exit 2)."""

import json

import numpy as np
import pytest

from antarium.ant.route_following import route_from_log
from antarium.ant.routes import Route
from antarium.ant.storage import FORMAT_VERSION
from antarium.cli import main


def test_learn_then_run_writes_model_log_pictures_and_summary(tmp_path, capsys):
    route = tmp_path / "route.csv"
    route.write_text("x_m,y_m\n0.5,-0.3\n0.7,-0.28\n")
    model = tmp_path / "ant.npz"
    assert main(["ant", "learn", "--route", str(route), "--spacing", "0.02", "--out", str(model),
                 "--log", str(tmp_path / "learn.h5")]) == 0
    assert "1875" in capsys.readouterr().out  # bytes per route MBON
    assert main(["ant", "run", str(model), "--out", str(tmp_path / "run"), "--heading-deg", "10"]) == 0
    for name in ("run.h5", "run_paths.png", "run_traces.png", "run.json"):
        assert (tmp_path / "run" / name).stat().st_size > 0
    summary = json.loads((tmp_path / "run" / "run.json").read_text())["summary"]
    assert summary["arrived"] and summary["decisions"] > 5
    # The path of an earlier trial log is a route too: the learning walk's log holds the route it walked.
    walked = route_from_log(tmp_path / "learn.h5")
    assert walked.length == pytest.approx(Route.load(route).length, abs=0.005)
    assert np.abs(Route.load(route).project(walked.points)[1]).max() < 1e-6


def test_a_route_with_one_point_is_refused(tmp_path, capsys):
    route = tmp_path / "one.csv"
    route.write_text("x_m,y_m\n0.5,0.5\n")
    assert main(["ant", "learn", "--route", str(route), "--out", str(tmp_path / "m.npz")]) == 2
    assert "at least two distinct points, got 1" in capsys.readouterr().err
    assert not (tmp_path / "m.npz").exists()


def test_a_model_file_of_another_version_is_refused(tmp_path, capsys):
    bad = tmp_path / "future.npz"
    np.savez(bad, format=np.array("antarium-ant-model"), version=np.array(FORMAT_VERSION + 1))
    assert main(["ant", "run", str(bad), "--out", str(tmp_path / "run")]) == 2
    assert f"version {FORMAT_VERSION + 1} cannot be read; allowed: 1, 2, {FORMAT_VERSION}" in capsys.readouterr().err


def test_unknown_models_and_parameters_are_refused(tmp_path, capsys):
    assert main(["ant", "evaluate", "--models", "antcar,infomax", "--out", str(tmp_path)]) == 2
    assert "allowed: antcar, ardin, perfect_memory" in capsys.readouterr().err
    assert main(["ant", "learn", "--route", "curved:1", "--param", "n_mbons=3", "--out", str(tmp_path / "m.npz")]) == 2
    assert "unknown antcar parameter" in capsys.readouterr().err
