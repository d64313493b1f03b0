"""`antarium ant learn | run | evaluate`: files written, bad input refused with a clear error (exit 2)."""

import json
from pathlib import Path

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
    # A run that never reaches the nest has no stopping distance: null in run.json, not NaN (no JSON reader takes)
    assert main(["ant", "run", str(model), "--out", str(tmp_path / "short"), "--max-decisions", "1"]) == 0
    short = json.loads((tmp_path / "short" / "run.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert short["summary"]["stop_distance"] is None and short["summary"]["decisions"] == 1
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


def test_params_are_converted_by_the_type_of_the_models_field():
    from antarium.commands.ant import _params

    assert _params(["avoid=False", "flow_gain=0.3", "n_kc=2e4", "flow_method=foe"], "cxmb") == {
        "avoid": False, "flow_gain": 0.3, "n_kc": 20_000, "flow_method": "foe"}
    converted = _params(["avoid=1", "noise=0", "seed=7"], "cx")
    assert converted == {"avoid": True, "noise": 0.0, "seed": 7}
    assert type(converted["noise"]) is float and type(converted["seed"]) is int
    assert _params(["avoid=TRUE"], "one_ring") == {"avoid": True} and _params(["avoid=0"], "cx") == {"avoid": False}


@pytest.mark.parametrize(("argv", "message"), [
    (["learn", "--route", "curved:1", "--param", "n_kc=1.5"], "antcar parameter n_kc must be an integer, got 1.5"),
    (["learn", "--model", "ardin", "--route", "curved:1", "--param", "seed=x"],
     "ardin parameter seed must be an integer, got 'x'"),
    (["learn", "--route", "curved:1", "--param", "k_v=nan"], "antcar parameter k_v must be a finite number, got nan"),
    (["arena", "--param", "avoid=maybe"], "cxmb parameter avoid must be true or false (or 1 or 0), got 'maybe'"),
    (["homing", "--param", "avoid=False=1"], "cx parameter avoid must be true or false"),
    (["learn", "--route", "curved:1", "--spacing", "0"],
     "--spacing must be > 0 m (leave it out for the default), got 0"),
    (["learn", "--route", "curved:1", "--spacing", "-0.02"], "--spacing must be > 0 m"),
    (["run", "no_such_model.npz", "--max-decisions", "0"],
     "--max-decisions must be > 0 (leave it out for the default)"),
    (["serve", "no_such_model.npz", "--config", "no.toml", "--max-decisions", "-3"], "--max-decisions must be > 0"),
    (["homing", "--compass", "sky", "--param", "compass=ideal", "--seeds", "1", "--steps", "2", "--inbound", "1"],
     "model parameter compass='ideal' differs from the task's compass 'sky'; choose the compass with --compass"),
    (["arena", "--compass", "ideal", "--param", "compass=sky", "--seeds", "1", "--steps", "2", "--inbound", "1"],
     "choose the compass with --compass"),
    (["homing", "--tether", "fixed", "--cue-wait-frames", "-1", "--seeds", "1", "--steps", "2"],
     "tether must be free_yaw or fixed and cue_wait_frames an integer >= 0, got 'fixed' and -1"),
    # NaN passed every check: put-back NaN evaluated every route never putting the ant back; a NaN or infinite
    # length ended in "cannot convert float NaN to integer"; a negative curved seed in numpy's own words
    (["evaluate", "--put-back-cm", "nan", "--routes", "1", "--length", "0.2", "--models", "antcar"],
     "--put-back-cm must be a finite number >= 0 (0: never put back), got nan"),
    (["evaluate", "--length", "nan"], "--length a finite number > 0 m, got 10 and nan"),
    (["learn", "--route", "curved:1", "--length", "inf"], "route length and spacing must be finite numbers > 0 m"),
    (["learn", "--route", "curved:-1"], "route 'curved:-1': use curved:SEED with an integer seed >= 0"),
    (["displace", "--lateral-cm", "nan", "--steps", "2"],
     "--lateral-cm must be a finite number (cm left of the feeder; negative: right), got nan"),
])
def test_bad_values_are_refused_in_one_line(tmp_path, capsys, argv, message):
    out = ["--out", str(tmp_path / ("m.npz" if argv[0] == "learn" else "out"))]
    assert main(["ant", *argv, *out]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not (tmp_path / "m.npz").exists()


def test_homing_in_the_fixed_tether_waits_for_its_sky_compass(tmp_path, capsys):
    """`ant homing --tether fixed`: the scene and its polarised sky turn with the ant, and the ant waits (up to
    `--cue-wait-frames`, default 60) for its compass while the polarisers turn; with 0 the trip ends at once."""
    for wait, lost in ((None, None), ("0", "outbound, decision 0: the sky compass has no cue")):
        out = tmp_path / f"wait{wait}"
        argv = ["ant", "homing", "--tether", "fixed", "--compass", "sky", "--seeds", "1", "--steps", "20",
                "--inbound", "10", "--out", str(out)] + ([] if wait is None else ["--cue-wait-frames", wait])
        assert main(argv) == 0
        record = json.loads((out / "pi_homing_sky.json").read_text())
        assert record["tether"] == "fixed" and record["cue_wait_frames"] == (60 if wait is None else 0)
        why = record["outcomes"][0]["lost_cue"]
        assert why is None if lost is None else why.startswith(lost)
    capsys.readouterr()


def test_a_compass_mismatch_is_refused_before_either_compass_runs(tmp_path, capsys):
    """--compass both with --param compass=sky: refused before the sky run (it ran and wrote its files, and the
    ideal run was refused after it)."""
    out = tmp_path / "out"
    argv = ["ant", "homing", "--compass", "both", "--param", "compass=sky", "--seeds", "1", "--steps", "2",
            "--inbound", "1", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "model parameter compass='sky' differs from the task's compass 'ideal'" in err and err.count("\n") == 1
    assert not out.exists()


def test_the_printed_homing_summary_is_the_strict_json_of_the_file(tmp_path, capsys):
    """A run whose metrics are NaN (every outbound ended without a cue) printed NaN, which no JSON reader takes,
    where the file holds null; the file lacked the pictures' paths that the print has."""
    out = tmp_path / "out"
    argv = ["ant", "homing", "--tether", "fixed", "--cue-wait-frames", "0", "--compass", "sky", "--seeds", "1",
            "--steps", "20", "--inbound", "10", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    summary = json.loads(printed[printed.index("\n{") + 1:], parse_constant=lambda c: pytest.fail(f"printed {c}"))
    assert summary["closest_approach_share_median"] is None and summary["runs_without_cue"]
    assert summary == json.loads((out / "pi_homing_sky.json").read_text())["summary"]
    assert Path(summary["paths_png"]).stat().st_size > 0


def test_run_refuses_a_central_complex_model_file_naming_its_kind(tmp_path, capsys):
    """A cx model file given to `ant run` walked into the habitat and ended on 'the sky compass has no cue';
    `ant serve` took it too."""
    from antarium.ant.eye import EyeParams
    from antarium.ant.models import make_model
    from antarium.ant.storage import save_model

    model = tmp_path / "cx.npz"
    save_model(model, make_model("cx", EyeParams().n_pn), EyeParams(), np.array([[0.0, 0.0], [0.5, 0.0]]))
    for argv in (["run", str(model)], ["serve", str(model), "--config", str(tmp_path / "no.toml")]):
        assert main(["ant", *argv, "--out", str(tmp_path / "out"), "--max-decisions", "3"]) == 2
        err = capsys.readouterr().err
        assert "holds a cx model; a route is followed by a route model (antcar, ardin, perfect_memory)" in err
        assert err.count("\n") == 1 and not (tmp_path / "out").exists()


def test_ant_demo_prints_its_figures_and_every_file_it_wrote(tmp_path, capsys):
    """`antarium ant demo` printed its summary as a raw dict in metres, named 2 of its 5 files, and its progress
    bar wrote a line per step into output that was not a terminal (a log file)."""
    assert main(["ant", "demo", "--out", str(tmp_path)]) == 0
    captured = capsys.readouterr()
    first, files = captured.out.strip().splitlines()
    assert first.startswith("virtual ant demo: antcar: lateral error ") and " cm, angular " in first, first
    written = sorted(p.name for p in tmp_path.iterdir())
    assert files == f"  wrote into {tmp_path.resolve()}: {', '.join(written)}"
    assert {"virtual_ant.h5", "virtual_ant_paths.png", "virtual_ant_traces.png", "virtual_ant_model.npz",
            "virtual_ant.json"} <= set(written)
    assert "step" not in captured.err  # no progress bar where the output is no terminal
