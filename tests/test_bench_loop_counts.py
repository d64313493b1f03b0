"""`antarium bench loop`'s figures say what they cover: the warm-up cut only when it was made, the counts beside the
kept frames over the same frames (or labelled "whole run"), and the monitor bench's page window ends with the frames."""

from __future__ import annotations

import argparse

import numpy as np

from antarium.bench.loop import WARMUP_S, _print, summarise

PERIOD = 1 / 190


def _frames(seconds: float) -> dict[str, np.ndarray]:
    n = int(round(seconds * 190))
    t = 5.0 + PERIOD * np.arange(n)
    return {"t_target": t, "t_start": t, "t_sent": t + 2e-3, "late": np.zeros(n, np.int8),
            "full_render": np.zeros(n, np.int8), "skipped": np.zeros(n, np.int64), "link_ok": np.ones(n, np.int8),
            "pacing_error": np.full(n, 1e-5), "latency": np.full(n, 3e-3),
            **{k: np.full(n, 2e-4) for k in ("render", "sample", "convert", "encode", "send")}}


def _report(result: dict) -> dict:  # what `_run_one` adds before printing
    return {**result, "commands": {}, "device": {"gpu_clocks": None},
            "config": {"render": {"scene": "habitat", "face_size_px": 0}, "keep_gpu_busy": "auto"}}


def test_a_short_run_says_that_nothing_was_excluded(capsys):
    short = summarise(_frames(1.9), 190.0)
    assert short["warmup_excluded"] is False and short["frames"] == 361
    _print(_report(short))
    text = capsys.readouterr().out
    assert "no warm-up excluded" in text and "excluded)" not in text.replace("no warm-up excluded", "")
    long = summarise(_frames(3.0), 190.0)
    assert long["warmup_excluded"] is True and long["warmup_s"] == WARMUP_S and long["frames"] == 570 - 190
    _print(_report(long))
    assert f"(first {WARMUP_S:g} s excluded)" in capsys.readouterr().out


def test_counts_beside_the_kept_frames_cover_them_or_say_whole_run(capsys):
    f = _frames(3.0)  # frames 0..189 are the warm-up
    f["link_ok"][[50, 51, 300, 400, 401]] = 0  # outages beginning at frames 50 (warm-up), 300 and 400
    f["full_render"][[0, 1, 2, 3, 250, 260]] = 1  # start-up in full, two more kept frames in full
    stats = {"link_outages": 3, "rejected_frames": 4, "gpu_busy_passes": 7,
             "far_layer": {"mode": "async", "layer_frames": 564, "full_frames": 6, "builds": 9, "error": ""}}
    r = summarise(f, 190.0, final_stats=stats)
    assert r["link_outages"] == 2 and r["link_outages_whole_run"] == 3
    assert r["far_layer"]["full_frames"] == 2 and r["far_layer"]["layer_frames"] == r["frames"] - 2
    assert r["far_layer"]["builds"] == 9 and r["far_layer"]["frames_counted"] == "kept frames"
    assert r["rejected_frames"] == 4 and r["gpu_busy_passes"] == 7
    assert {"rejected_frames", "gpu_busy_passes", "far_layer.builds"} <= set(r["whole_run"])
    _print(_report(r))
    text = capsys.readouterr().out
    assert "link outages 2   rejected frames 4 (whole run)" in text
    assert f"{r['frames'] - 2} frames with it, 2 in full (start-up, edits, eye jumps), 9 layers built (whole run)" \
        in text
    assert "7 busy passes between frames, whole run" in text
    # a table without the far layer's column: the renderer's counts, labelled
    del f["full_render"]
    old = summarise({**f, "full_render": np.zeros(570, np.int8)}, 190.0)  # summarise itself needs the column
    assert old["far_layer"] is None
    from antarium.bench.loop import _run_counts

    layer = _run_counts(f, np.ones(570, bool), stats)["far_layer"]
    assert layer["frames_counted"] == "whole run" and layer["full_frames"] == 6


def test_each_late_frame_is_listed_with_its_stages_and_the_commands_around_it(capsys):
    """Late frames one by one (when, which stage, how late it began), and a scripted command whose window holds
    one named beside it: what told a scene swap's late start (16 ms) from a slow GPU stage on an H100."""
    f = _frames(3.0)
    f["late"][[100, 300, 500]] = 1  # one in the warm-up: not listed
    f["pacing_error"][300] = 16e-3
    f["sample"][500] = 19e-3
    f["t_sent"][500] = f["t_start"][500] + 21e-3
    f["skipped"][[300, 500]] = [3, 4]
    r = summarise(f, 190.0)
    assert [round(row["t_s"], 3) for row in r["late_list"]] == [round(300 * PERIOD, 3), round(500 * PERIOD, 3)]
    first, second = r["late_list"]
    assert first["pacing_ms"] == 16.0 and first["skipped"] == 3
    assert second["sample_ms"] == 19.0 and round(second["work_ms"], 6) == 21.0
    report = _report(r)
    report["commands"] = {"load_scene": {"sent": 1, "cut_by_the_end": 0, "errors": [], "reply": None,
                                         "late_frames_around": 1, "frames_around": 10, "full_frames_around": 10,
                                         "times_s": [[300 * PERIOD - 1.0, 300 * PERIOD - 0.002]]}}
    _print(report)
    lines = [ln for ln in capsys.readouterr().out.splitlines() if "late frame  " in ln]
    assert len(lines) == 2 and "pacing error 16.00 ms, 3 slot(s) skipped" in lines[0]
    assert "load_scene sent 1.00 s and replied 0.00 s before" in lines[0] and "load_scene" not in lines[1]
    assert "sample 19.00" in lines[1]


def test_the_loop_bench_says_when_its_frames_end_before_it_reports(tmp_path, capsys, monkeypatch):
    from antarium.bench import loop

    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    calls = []

    def frames_end():
        calls.append(1)
        print("FRAMES ENDED")

    loop.run(argparse.Namespace(seconds=None, frames=30, json_out=None, machine_probe=False,
                                on_frames_end=frames_end))
    text = capsys.readouterr().out
    assert calls == [1]
    assert text.index("FRAMES ENDED") < text.index("loop bench:")
