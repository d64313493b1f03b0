"""`antarium bench jitter`: the machine's wake-up lateness and stalls, and the frame slots they would cost."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from antarium.bench.jitter import PROBE_PERIOD_S, STALL_S, measure, overlapping, summarise

PERIOD, WORK, STEP = 5e-3, 2.5e-3, 10e-6


class ScriptedClock:
    """Each reading advances the time by STEP; a sleep wakes late by the next scripted lateness; `stalls` maps a
    reading's number to a gap inserted before it (the thread did not run)."""

    def __init__(self, late: list[float], stalls: dict[int, float]) -> None:
        self.t, self.late, self.stalls, self.readings, self.targets = 0.0, list(late), stalls, 0, []

    def now(self) -> float:
        self.readings += 1
        self.t += self.stalls.get(self.readings, 0.0)
        t, self.t = self.t, self.t + STEP
        return t

    def sleep_until(self, t: float) -> None:
        self.targets.append(t)
        self.t = max(self.t, t) + self.late.pop(0)


def test_lateness_stalls_and_missed_slots_are_measured_as_scripted():
    late = [0.0, 0.0, 3e-3, 6e-3, 0.0]
    clock = ScriptedClock(late, stalls={})
    # a 1 ms gap in slot 1's busy reading (one reading before the first slot, about WORK / STEP + 1 in each)
    clock.stalls = {1 + int(round(WORK / STEP)) + 1 + 5: 1e-3}
    lateness, stalled = measure(clock, PERIOD, WORK, slots=len(late))

    np.testing.assert_allclose(lateness, late, atol=1e-12)
    assert stalled[0] == 0 and stalled[2:].sum() == 0
    assert stalled[1] == pytest.approx(1e-3 + STEP)
    # slots on the period grid; the 3 and 6 ms late ones (work ends 5.5 and 8.5 ms after them) skip the slot
    # they overran
    steps = np.round(np.diff(clock.targets) / PERIOD, 9)
    np.testing.assert_array_equal(steps, [1, 1, 2, 2])

    r = summarise(lateness, stalled, PERIOD, WORK)
    # slot 1: 0 + 2.5 + 1.01 ms < 5 ms on time; slots 2 and 3: 3 and 6 ms late + 2.5 ms of work > 5 ms, missed
    assert r["missed_slots"] == 2
    assert r["slots_with_stalls"] == 1 and r["stall_max_ms"] == pytest.approx(1.01)
    assert r["lateness_at_least_ms"] == {"0.5": 2, "1": 2, "2": 2, "5": 1}
    assert r["lateness"]["max_ms"] == pytest.approx(6.0)


def test_gaps_shorter_than_the_stall_threshold_are_not_stalls():
    clock = ScriptedClock([0.0, 0.0], stalls={3: STALL_S / 2})
    _, stalled = measure(clock, PERIOD, WORK, slots=2)
    assert stalled.sum() == 0


def test_the_cli_runs_on_this_machine_and_writes_its_figures(tmp_path):
    out = tmp_path / "jitter.json"
    run = subprocess.run([sys.executable, "-m", "antarium", "bench", "jitter", "--frames", "40", "--work-ms", "1",
                          "--json", str(out)], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "missed slots" in run.stdout
    r = json.loads(out.read_text())
    assert r["slots"] == 40 and r["work_ms"] == 1.0 and r["rate_hz"] == 190.0
    assert 0 <= r["missed_slots"] <= 40 and r["lateness"]["p50_ms"] >= 0


def test_work_longer_than_a_frame_is_refused_with_the_allowed_range():
    run = subprocess.run([sys.executable, "-m", "antarium", "bench", "jitter", "--frames", "5", "--work-ms", "6"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode != 0
    assert "--work-ms must be in [0, 5.26) ms" in run.stderr


def test_frames_overlapping_a_stall_are_found():
    stalls = np.array([[1.0, 0.002], [2.0, 0.010], [3.0, 0.0006]])  # [slot time, lateness] s
    t0 = np.array([0.990, 0.999, 1.0021, 1.998, 2.005, 2.011, 2.999])
    t1 = t0 + 0.003
    np.testing.assert_array_equal(overlapping(t0, t1, stalls), [False, True, False, True, True, False, True])
    assert not overlapping(t0, t1, np.empty((0, 2))).any()


def test_loop_bench_tells_the_machines_late_frames_from_the_loops_own():
    from antarium.bench.loop import summarise

    period = 1 / 190
    n = 1000
    t_target = 10.0 + period * np.arange(n)
    late = np.zeros(n, dtype=np.int8)
    late[[300, 600, 900]] = 1
    frames = {"t_target": t_target, "t_start": t_target + 1e-5, "t_sent": t_target + np.where(late, 6e-3, 2e-3),
              "late": late, "full_render": np.zeros(n, np.int8), "skipped": late.astype(np.int64),
              "link_ok": np.ones(n, np.int8), "pacing_error": np.full(n, 1e-5), "latency": np.full(n, 3e-3),
              **{k: np.full(n, 2e-4) for k in ("render", "sample", "convert", "encode", "send")}}
    # CPU 1 stopped for 4 ms at frame 300's slot and 0.6 ms between frames; CPU 0 for 7 ms at frame 600's slot
    stalls = {1: (True, np.array([[t_target[300] + 1e-4, 4e-3], [t_target[450] + 2.5e-3, 0.6e-3]])),
              0: (True, np.array([[t_target[600] - 5e-4, 7e-3]]))}
    m = summarise(frames, 190.0, stalls)["machine"]
    assert m["late_frames_in_stalls"] == 2 and m["late_frames_own"] == 1  # frame 900 is the loop's own
    # frames from a probe period (2 ms) before their slot to their last datagram: 300 and 301, 600 and 601 (their
    # windows open 3.3 ms after 300's and 600's slots); the 0.6 ms stall falls between frame 450's last datagram and
    # frame 451's window
    assert PROBE_PERIOD_S == 2e-3
    assert m["frames_in_stalls"] == 4
    assert m["probes"]["1"]["late_wakeups_at_least_ms"] == {"0.5": 2, "1": 1, "2": 1, "5": 0}
    assert m["probes"]["0"]["max_ms"] == pytest.approx(7.0)


def test_stall_probes_run_on_each_cpu_and_report_their_late_wake_ups():
    import os
    import time

    from antarium.bench.jitter import PROBE_THRESHOLD_S, StallProbes

    cpus = sorted(os.sched_getaffinity(0))
    probes = StallProbes(cpus, priority=0)
    time.sleep(0.5)
    out = probes.stop()
    assert sorted(out) == cpus
    for realtime, events in out.values():
        assert realtime is False and events.ndim == 2 and events.shape[1] == 2
        assert (events[:, 1] >= PROBE_THRESHOLD_S).all()
