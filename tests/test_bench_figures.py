"""Figures of the smaller benchmarks, on fakes at the lowest seam: what `bench ant` prints of its perfect-memory
model, `bench jitter`'s longest stall, `bench protocol`'s achieved rate and `bench monitor`'s page window."""

from __future__ import annotations

import argparse

import numpy as np
import pytest


def test_ant_bench_prints_and_stores_the_views_the_perfect_memory_model_learned(capsys, monkeypatch):
    from antarium.bench import ant

    result = {k: 1.0 for k in ("antcar_decisions_per_s", "antcar_model_only_decisions_per_s",
                               "antcar_learn_views_per_s", "ardin_decisions_per_s", "ardin_ms_per_decision",
                               "perfect_memory_decisions_per_s", "perfect_memory_ms_per_decision", "eye_views_per_s",
                               "compass_cx_step_per_s", "compass_per_s")}
    result.update(perfect_memory_learned_views=7, one_core=True, bytes_per_route_mbon=1, bytes_per_place_mbon=1,
                  ratios={k: 1.0 for k in ("decisions_vs_goal_1000", "decisions_vs_dome_190", "learning_vs_goal_100",
                                           "learning_vs_dome_190", "route_mbon_bytes_vs_goal_2000")},
                  ratios_cx={k: 1.0 for k in ("compass_cx_vs_goal_10000", "cx_vs_goal_1000", "cxmb_vs_goal_1000",
                                              "one_ring_vs_goal_1000")},
                  **{f"{k}_{f}": 1 for k in ("cx", "cxmb", "one_ring") for f in ("decisions_per_s", "memory_bytes")})
    asked = []
    monkeypatch.setattr(ant, "measure_on_one_core", lambda s, n: asked.append(n) or result)
    ant.run(argparse.Namespace(seconds=0.1, frames=7, json_out=None))
    text = capsys.readouterr().out
    assert asked == [7] and "perfect memory decisions (7 views):" in text and "20 views" not in text


def test_the_perfect_memory_model_learns_the_frames_it_is_given():
    from antarium.bench.ant import measure_on_one_core

    assert measure_on_one_core(0.001, 3)["perfect_memory_learned_views"] == 3


class ScriptedClock:  # as tests/test_server_jitter.py: each reading advances STEP; `stalls`: reading -> gap before it
    def __init__(self, stalls: dict[int, float]) -> None:
        self.t, self.stalls, self.readings = 0.0, stalls, 0

    def now(self) -> float:
        self.readings += 1
        self.t += self.stalls.get(self.readings, 0.0)
        t, self.t = self.t, self.t + 10e-6
        return t

    def sleep_until(self, t: float) -> None:
        self.t = max(self.t, t)


def test_jitter_reports_the_longest_single_gap_not_a_slots_sum(capsys):
    from antarium.bench.jitter import _print, measure, summarise

    period, work = 5e-3, 2.5e-3
    clock = ScriptedClock({10: 0.6e-3, 20: 0.7e-3})  # two gaps in the first slot's work, 1.3 ms in all
    longest = np.zeros(2)
    lateness, stalled = measure(clock, period, work, 2, longest)
    assert longest[0] == pytest.approx(0.71e-3) and stalled[0] == pytest.approx(1.32e-3)
    r = summarise(lateness, stalled, period, work, longest)
    assert r["stall_max_ms"] == pytest.approx(0.71) and r["stalled_slot_max_ms"] == pytest.approx(1.32)
    assert r["stall_max_is_slot_sum"] is False
    r.update(rate_hz=200.0, setup={"cpu": None, "realtime_priority": 0, "notes": []}, steal_s=None,
             machine={"cpuidle_driver": None, "cpuidle_governor": None, "rt_runtime_us": None, "rt_period_us": None})
    _print(r)
    assert "the longest gap 0.71 ms; at most 1.32 ms stalled in one slot" in capsys.readouterr().out


def test_jitter_with_seconds_and_frames_measures_whichever_ends_first(monkeypatch, capsys):
    from antarium.bench import jitter

    asked = []

    def fake_measure(clock, period, work, slots, longest=None):
        asked.append(slots)
        return np.zeros(slots), np.zeros(slots)

    monkeypatch.setattr(jitter, "measure", fake_measure)
    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    jitter.run(argparse.Namespace(seconds=0.1, frames=500, work_ms=None, json_out=None))
    jitter.run(argparse.Namespace(seconds=10.0, frames=50, work_ms=None, json_out=None))
    assert asked == [19, 50]  # 0.1 s at 190 Hz: 19 slots


def test_protocol_rate_counts_the_periods_between_the_first_and_last_frame():
    from antarium.bench.protocol import achieved_rate

    assert achieved_rate([10.0 + k / 190 for k in range(950)]) == pytest.approx(190.0)
    assert achieved_rate([0.0, 0.5]) == pytest.approx(2.0)
    assert np.isnan(achieved_rate([1.0]))


def test_the_page_figures_cover_the_measuring_window_only():
    from antarium.bench.monitor import page_figures

    # the page's rolling `latencies` (warm-up frames among them) is not used: `measured` holds the window's frames
    m = {"drawn": 4, "measured": [0.010, 0.020, 0.030, 0.040], "latencies": [5.0, 5.0, 0.010, 0.020, 0.030, 0.040],
         "paint": [120.0], "first_draw_ms": 300.0, "draw_ms": [[1.0, 2.0], [3.0, 4.0]]}
    r = page_figures(m, seconds=2.0, cpu_s=0.5)
    assert r["updates_per_s"] == 2.0 and r["browser_cpu_ms_per_update"] == 125.0
    assert r["frame_to_screen_ms"]["n"] == 4 and r["frame_to_screen_ms"]["max"] == pytest.approx(40.0)
    assert r["draw_ms_p50"] == {"map": 2.0, "3d": 3.0}


def test_the_page_keeps_every_latency_of_the_measuring_window():
    from pathlib import Path

    import antarium.monitor

    page = (Path(antarium.monitor.__file__).parent / "page.html").read_text()
    assert "if (M.measured) M.measured.push(lat);" in page
