"""`antarium bench` as a lab uses it: bad durations and output names refused in one line before any work, Ctrl-C
says what was kept, and every JSON file has the same header and is strict JSON. No timing is asserted."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from antarium.cli import main


def _one_line(capsys) -> str:
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert captured.out == "" and "\n" not in err, (captured.out, err)  # nothing measured, one line
    assert err.startswith("antarium bench: error: ")
    return err


@pytest.mark.parametrize("args, said", [
    (["jitter", "--seconds", "1e300"], "--seconds must be at most 86400 seconds (a day), got 1e+300"),
    (["ant", "--seconds", "1e9"], "--seconds must be at most 86400 seconds (a day), got 1e+09"),
    (["render", "--frames", "100000000000"], "--frames must be from 1 to 16,416,000 (a day at 190 frames/s), got "
                                             "100000000000"),
    (["jitter", "--seconds", "0.001"], "--seconds must be at least one frame slot (5.26 ms at 190 Hz), got 0.001"),
    (["loop", "--seconds", "1", "--load-every", "0"], "--load-every must be a positive number of seconds, got 0"),
    (["loop", "--seconds", "1", "--sky-every", "nan"], "--sky-every must be a positive number of seconds, got nan"),
])
def test_a_duration_out_of_range_is_refused_in_one_line_before_any_work(args, said, capsys, monkeypatch):
    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    assert main(["bench", *args]) == 2
    assert said in _one_line(capsys)


def test_a_json_name_without_json_ending_is_refused(tmp_path, capsys):
    assert main(["bench", "jitter", "--frames", "2", "--json", str(tmp_path / "figures")]) == 2
    assert "--json file must end in .json, got 'figures'" in _one_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_a_json_file_that_cannot_be_made_is_refused_before_the_benchmark(capsys):
    # /proc: a folder that exists and says it is writable, where no file can be made
    assert main(["bench", "jitter", "--frames", "2", "--json", "/proc/antarium-bench.json"]) == 2
    assert "--json '/proc/antarium-bench.json': cannot write there" in _one_line(capsys)


@pytest.mark.parametrize("option", ["--out", "--cube"])
def test_render_refuses_a_picture_that_cannot_be_made_before_rendering(option, tmp_path, capsys):
    args = ["render", "grating", "--out", str(tmp_path / "view.png"), option, "/proc/antarium-view.png"]
    assert main(args) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and captured.err.strip() == (
        f"antarium render: error: {option} '/proc/antarium-view.png': cannot write there (No such file or "
        "directory); give a file in a folder where files can be made")
    assert list(tmp_path.iterdir()) == []


def test_every_json_file_has_the_run_header_and_is_strict_json(tmp_path):
    from antarium import __version__
    from antarium.bench import write_json

    out = tmp_path / "x.json"
    write_json(out, "experiment", {"a": float("nan"), "b": [1.0, float("inf")], "c": {"d": 2}})
    r = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"{c} is not JSON"))
    assert r["a"] is None and r["b"] == [1.0, None] and r["c"] == {"d": 2}
    assert r["run"]["bench"] == "experiment" and r["run"]["antarium"] == __version__
    assert r["run"]["cpus"] == os.cpu_count() and r["run"]["host"]


def test_bench_jitter_says_what_it_measures_first_and_its_json_has_the_run_header(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    out = tmp_path / "jitter.json"
    assert main(["bench", "jitter", "--frames", "3", "--work-ms", "0.5", "--json", str(out)]) == 0
    assert capsys.readouterr().err.startswith("bench jitter: measuring 3 frame slots (0.0 s) ...\n")
    r = json.loads(out.read_text())
    assert r["run"]["bench"] == "jitter" and r["slots"] == 3


def test_bench_experiment_refuses_too_few_runs_to_measure_the_overhead(capsys):
    assert main(["bench", "experiment", "--frames", "2", "--seconds", "0.01"]) == 2
    assert "--frames (the number of runs) must be at least 3, got 2" in _one_line(capsys)


def _interrupted(args: list[str], until: str, stream: str = "stderr", settle_s: float = 0.0) -> tuple:
    """`antarium bench ARGS`, sent Ctrl-C once a line of its `stream` starts with `until` (and `settle_s` later):
    (exit status, the rest of its stdout, the rest of its stderr, that line). Killed should the line never come."""
    env = {k: v for k, v in os.environ.items() if k != "ANTARIUM_RIG_CONFIG"}
    bench = subprocess.Popen([sys.executable, "-m", "antarium", "bench", *args], stdout=subprocess.PIPE,
                             stderr=subprocess.PIPE, text=True, env=env,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    guard = threading.Timer(300.0, bench.kill)
    guard.start()
    seen = ""
    try:
        for line in getattr(bench, stream):
            if line.startswith(until):
                seen = line
                break
        time.sleep(settle_s)
        bench.send_signal(signal.SIGINT)
        out, err = bench.communicate(timeout=60)
    finally:
        guard.cancel()
        if bench.poll() is None:
            bench.kill()
            bench.wait()
    return bench.returncode, out, err, seen


def test_ctrl_c_ends_the_bench_with_one_line_saying_what_was_kept(tmp_path):
    out = tmp_path / "render.json"
    code, _, err, _ = _interrupted(["render", "--frames", "1000000", "--json", str(out)],
                                   "bench render: building the scenes")  # the benchmark has begun
    assert code == 130
    last = err.strip().splitlines()[-1]
    assert last.startswith("antarium bench render: interrupted (Ctrl-C) before its end: what it measured is printed")
    assert not out.exists()


def test_ctrl_c_during_bench_loop_reports_and_writes_the_frames_run_so_far(tmp_path):
    out = tmp_path / "loop.json"
    # some frames after the line (not a timing assertion: any number >= 2 will do)
    code, text, err, _ = _interrupted(["loop", "--seconds", "600", "--json", str(out)],
                                      "bench loop: frames running for 600 s", settle_s=2.0)
    assert code == 130, err
    r = json.loads(out.read_text())
    assert r["interrupted"] is True and r["frames"] >= 2 and r["run"]["bench"] == "loop"
    assert f"loop bench INTERRUPTED (Ctrl-C): the figures below are over the {r['frames']} frames" in text
    assert f"loop bench: {r['frames']} frames over" in text and f"figures written to {out}" in text


def test_ctrl_c_during_bench_render_reports_and_writes_the_workloads_measured(tmp_path):
    out = tmp_path / "render.json"
    code, text, err, row = _interrupted(["render", "--path", "cpu", "--frames", "3000", "--json", str(out)],
                                        "cpu ", stream="stdout")  # the first workload's row: one measured
    assert code == 130, err
    r = json.loads(out.read_text())
    assert r["interrupted"] is True and r["run"]["bench"] == "render"
    measured = len(r["results"])
    assert 1 <= measured < 5 and f"INTERRUPTED (Ctrl-C): {measured} of the 5 workloads measured" in text
    assert r["results"][0]["workload"] == "panorama" and row.split()[:2] == ["cpu", "panorama"]
    assert f"figures written to {out}" in text
