"""`antarium bench loop --machine-probe`'s stall probes: they stay on their CPU when the server's CPU placement moves
every process of ours off the loop's CPU, and say where they ran; only stalls on the loop's CPU make a late frame the
machine's, and with a probe that is not real-time the split is unknown."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from antarium.bench.jitter import ProbeReport, StallProbes
from antarium.bench.loop import _print, summarise

PERIOD = 1 / 190


def _frames(n: int = 1000, late_at=(300, 600, 900)) -> dict[str, np.ndarray]:
    t_target = 10.0 + PERIOD * np.arange(n)
    late = np.zeros(n, dtype=np.int8)
    late[list(late_at)] = 1
    return {"t_target": t_target, "t_start": t_target + 1e-5, "t_sent": t_target + np.where(late, 6e-3, 2e-3),
            "late": late, "full_render": np.zeros(n, np.int8), "skipped": late.astype(np.int64),
            "link_ok": np.ones(n, np.int8), "pacing_error": np.full(n, 1e-5), "latency": np.full(n, 3e-3),
            **{k: np.full(n, 2e-4) for k in ("render", "sample", "convert", "encode", "send")}}


def _stalls(frames, realtime=True) -> dict[int, ProbeReport]:
    t = frames["t_target"]
    # CPU 1 stopped for 4 ms at frame 300's slot; CPU 0 for 7 ms at frame 600's slot
    return {1: ProbeReport(realtime, np.array([[t[300] + 1e-4, 4e-3]]), {1: 500}, 0),
            0: ProbeReport(realtime, np.array([[t[600] - 5e-4, 7e-3]]), {0: 480, 1: 20}, 1)}


def _report(result: dict) -> dict:  # what `_run_one` adds before printing
    return {**result, "commands": {}, "device": {"gpu_clocks": None},
            "config": {"render": {"scene": "habitat", "face_size_px": 0}, "keep_gpu_busy": "auto"}}


def test_only_stalls_on_the_loops_cpu_make_a_late_frame_the_machines(capsys):
    frames = _frames()
    everywhere = summarise(frames, 190.0, _stalls(frames))["machine"]  # the loop has no CPU of its own
    assert everywhere["late_frames_in_stalls"] == 2 and everywhere["late_frames_own"] == 1
    r = summarise(frames, 190.0, _stalls(frames), loop_cpus={1})
    m = r["machine"]
    assert m["late_frames_in_stalls"] == 1 and m["late_frames_own"] == 2  # CPU 0's stall is not the loop's CPU
    assert m["loop_cpus"] == [1] and m["probes"]["0"]["counted"] is False and m["probes"]["1"]["counted"] is True
    assert m["probes"]["0"]["max_ms"] == pytest.approx(7.0)  # still reported, per CPU
    _print(_report(r))
    text = capsys.readouterr().out
    assert "1 overlap a machine stall on the loop's CPU 1 (the machine's), 2 do not (the loop's own)" in text
    assert "machine, CPU 0" in text and "not the loop's CPU, not counted below" in text
    assert "moved off CPU 0 1 times and pinned back: 20 on CPU 1 of its 500 wake-ups, not counted" in text


def test_with_a_probe_that_is_not_realtime_the_split_is_unknown(capsys):
    frames = _frames()
    r = summarise(frames, 190.0, _stalls(frames, realtime=False), loop_cpus={1})
    m = r["machine"]
    assert m["late_frames_in_stalls"] is None and m["late_frames_own"] is None
    assert m["probes_not_realtime"] == [0, 1]
    _print(_report(r))
    text = capsys.readouterr().out
    assert "the machine's and the loop's own: unknown" in text and "the machine's)" not in text


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="needs Linux and two CPUs")
def test_each_probe_runs_on_its_cpu_after_the_servers_placement_moved_it():
    from antarium.core import realtime

    cpus = sorted(os.sched_getaffinity(0))
    probes = StallProbes(cpus, priority=0)
    pids = probes.pids
    isolation = realtime.Isolation("auto")  # what `[loop] cpu = "auto"` does once the frames begin
    seen: dict[int, set[int]] = {}
    try:
        deadline = time.monotonic() + 20  # a probe process takes a moment to start (spawn)
        while time.monotonic() < deadline and not all(os.sched_getaffinity(p) == {c} for c, p in pids.items()):
            time.sleep(0.05)
        isolation.apply(threading.get_native_id())  # every child process of ours to the other CPUs
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and not all(os.sched_getaffinity(p) == {c} for c, p in pids.items()):
            time.sleep(0.05)
        seen = {c: os.sched_getaffinity(p) for c, p in pids.items()}
        time.sleep(0.3)  # wake-ups on their own CPUs again
    finally:
        isolation.release()
        out = probes.stop()
    assert seen == {c: {c} for c in cpus}  # each pinned itself back
    for c, report in out.items():
        assert report.ran_on.get(c, 0) > 0  # the CPU its line names, where its counted wake-ups ran
        if c == isolation.cpu:
            assert report.moved >= 1  # it was moved off and said so
    assert sum(r.moved for r in out.values()) >= 1
