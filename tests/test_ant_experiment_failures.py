"""An experiment's run under failures, as a review found them (issue 21): two commands on one results folder, a
results table with a failed run read back with its integer and boolean columns, a run's file holding another run's
row, Ctrl-C in a terminal and a --scheduler address where no scheduler answers."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
import tomllib

import pytest
from conftest import write_world_panorama

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")

from antarium.ant.experiment.results import load_results, report  # noqa: E402
from antarium.ant.experiment.runner import RUNS_DIR, run_experiment, run_path  # noqa: E402
from antarium.ant.experiment.spec import expand  # noqa: E402

SPEC = """
[experiment]
face_size = 55
max_decisions = 6
eye = {cols = 10, rows = 4}
[[worlds]]
scene = "pano.png"
[[route_sets]]
paths = "routes"
[models.ardin]
n_kc = 100
[models.perfect_memory]
"""


@pytest.fixture()
def pano(tmp_path):
    """A panorama world (pano.png), a route folder with two short routes and the spec (spec.toml)."""
    write_world_panorama(tmp_path / "pano.png")
    (tmp_path / "routes").mkdir()
    for i in range(2):
        (tmp_path / "routes" / f"r{i}.csv").write_text(f"x_m,y_m\n0,{0.1 * i}\n0.1,{0.1 * i}\n0.2,{0.1 * i + 0.02}\n")
    (tmp_path / "spec.toml").write_text(SPEC)
    return tmp_path


def _runs(d):
    return expand(tomllib.loads(SPEC), d).runs


def test_a_second_command_on_the_same_out_is_refused_while_one_runs(pano):
    """Two commands on one --out both ran every run (20 of 20 each, measured): the second is refused in one line
    while the first runs, and the folder is free again once it is over."""
    runs, out = _runs(pano), pano / "out"
    refused = []

    def second(row):
        if not refused:
            with pytest.raises(RuntimeError, match=r"is in use by another experiment .*pid \d+.*another --out") as e:
                run_experiment(runs, out, serial=True, progress_bar=False)
            refused.append(str(e.value))

    p = run_experiment(runs, out, serial=True, progress_bar=False, on_row=second)
    assert (p.done, p.failed) == (len(runs), 0) and len(refused) == 1
    assert run_experiment(runs, out, serial=True, progress_bar=False).skipped == len(runs)


def test_the_results_table_keeps_integers_and_booleans_beside_a_failed_run(pano):
    """A failed run has no metrics: its row's gaps made errors, decisions, memory_bytes floats and arrived an object
    column of True/False/None (a mask df[df.arrived] raised); they are nullable integers and booleans, and the
    report and its pictures are made from them."""
    exp, out = expand(tomllib.loads(SPEC), pano), pano / "out"
    runs = exp.runs
    (pano / "routes" / "r0.csv").write_text("x_m,y_m\n0,0\n0.3,0\n")   # edited after the spec was read: fails
    p = run_experiment(runs, out, serial=True, progress_bar=False)
    assert p.failed == 2 and p.done == 2
    df = load_results(out)
    for col in ("errors", "decisions", "memory_bytes", "learned_views", "seed"):
        assert pd.api.types.is_integer_dtype(df[col]), (col, df[col].dtype)
    assert pd.api.types.is_bool_dtype(df["arrived"])
    assert df[df.arrived.fillna(False)].status.eq("done").all()
    assert df.loc[df.status == "failed", "errors"].isna().all()
    report(out, exp.routes, exp.metrics, [r.run_id for r in runs])
    back = pd.read_parquet(out / "results.parquet")
    assert back.errors.dtype == "Int64" and back.arrived.dtype == "boolean"
    assert (out / "worst_and_best_paths.png").stat().st_size > 0


def test_a_runs_file_holding_another_runs_row_is_not_done(pano):
    """A file under one run's name holding another run's row (copied or renamed by hand) was counted as done: that
    run never ran and the results held the other run twice."""
    runs, out = _runs(pano), pano / "out"
    run_experiment(runs, out, serial=True, progress_bar=False)
    shutil.copy(run_path(out, runs[1].run_id), run_path(out, runs[0].run_id))
    p = run_experiment(runs, out, serial=True, progress_bar=False)
    assert (p.skipped, p.done) == (len(runs) - 1, 1)
    assert sorted(load_results(out).run_id) == sorted(r.run_id for r in runs)


def _command(pano, *flags):
    return subprocess.Popen([sys.executable, "-m", "antarium.cli", "ant", "experiment", str(pano / "spec.toml"),
                             "--out", str(pano / "out"), *flags], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)


def test_ctrl_c_on_local_workers_is_one_quiet_stop(pano):
    """Ctrl-C in a terminal reaches the command and its local workers (one process group): each worker printed a
    KeyboardInterrupt traceback (40 lines with 2 workers). The command stops the workers; rows written are kept."""
    proc = _command(pano, "--workers", "2")
    runs = pano / "out" / RUNS_DIR
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and not (runs.is_dir() and any(runs.glob("*.parquet"))):
        time.sleep(0.05)
    os.killpg(proc.pid, signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode in (0, 130)
    assert "Traceback" not in err and "KeyboardInterrupt" not in err, err[-2000:]


def test_a_scheduler_that_does_not_answer_is_one_line_naming_the_flag(pano):
    """--scheduler where nothing listens: one line naming --scheduler and what to do, after SCHEDULER_TIMEOUT_S."""
    from antarium.ant.experiment import runner

    proc = _command(pano, "--scheduler", "tcp://127.0.0.1:9")
    t0 = time.monotonic()
    _, err = proc.communicate(timeout=120)
    lines = [ln for ln in err.replace("\r", "\n").splitlines() if ln.startswith("antarium")]
    assert proc.returncode == 2 and len(lines) == 1, err
    assert "--scheduler tcp://127.0.0.1:9" in lines[0] and "dask scheduler" in lines[0], lines[0]
    assert time.monotonic() - t0 < runner.SCHEDULER_TIMEOUT_S + 20


def _hangs_on_ardin_r1(run):
    """A worker's task (`execute.run_task`) whose ardin run on route r1 hangs after it started (a GL driver that
    never returns); every other run runs as it would."""
    from antarium.ant.experiment.execute import announce_start, run_task

    if run.model == "ardin" and run.route == "r1":
        announce_start(run)
        time.sleep(3600)
    return run_task(run)


def test_a_run_that_hangs_is_recorded_failed_at_run_timeout_and_the_others_finish(pano):
    """A hung run held up the whole sweep for ever: with run_timeout_s it is recorded failed (RunTimeout), its worker
    restarted, and the other runs finish; without Dask a timeout is refused, as is a timeout that is no time."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the task, to workers that cannot import tests/
    runs, out = _runs(pano), pano / "out"
    rows = []
    p = run_experiment(runs, out, workers=2, progress_bar=False, run_timeout_s=30.0, task=_hangs_on_ardin_r1,
                       on_row=rows.append)
    assert (p.done, p.failed) == (len(runs) - 1, 1), rows
    (failed,) = [r for r in rows if r["status"] == "failed"]
    assert (failed["model"], failed["route"]) == ("ardin", "r1")
    assert failed["error"].startswith("RunTimeout: the run was still running after ")
    assert "(--run-timeout-s 30); its worker was restarted" in failed["error"]
    df = load_results(out)
    assert sorted(df.run_id) == sorted(r.run_id for r in runs) and (df.status == "done").sum() == len(runs) - 1
    for bad in (0, -1.0, float("nan"), "x"):
        with pytest.raises(ValueError, match="--run-timeout-s must be a finite number of seconds > 0"):
            run_experiment(runs, out, workers=2, progress_bar=False, run_timeout_s=bad)
    with pytest.raises(ValueError, match="--run-timeout-s needs Dask workers"):
        run_experiment(runs, out, serial=True, progress_bar=False, run_timeout_s=10.0)
