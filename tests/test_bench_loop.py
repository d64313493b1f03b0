"""`antarium bench loop` end to end on the embedded default rig (one short run): it prints its report and writes
the same figures as JSON. No timing is asserted; the figures are the benchmark's, not the test's."""

import argparse
import json

from antarium.cli import main


def test_loop_bench_reports_and_writes_its_figures(tmp_path, capsys, monkeypatch):
    monkeypatch.delenv("ANTARIUM_RIG_CONFIG", raising=False)
    out = tmp_path / "loop.json"
    assert main(["bench", "loop", "--seconds", "1", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    result = json.loads(out.read_text())
    assert f"loop bench: {result['frames']} frames over" in text and "face size default" in text
    assert result["frames"] > 0 and result["target_rate_hz"] == 190 and result["link_outages"] == 0
    assert {"render", "sample", "send"} <= set(result["stages"])
    assert f"{result['achieved_rate_hz']:.1f} / 190 Hz" in text
    assert f"GL renderer: {result['device']['gl_renderer']}; per-LED path: {result['device']['path']}" in text


def test_a_command_cut_short_by_the_runs_end_is_no_error_and_no_reply_time():
    import numpy as np

    from antarium.bench.loop import ScriptedCommands

    script = ScriptedCommands(None, "habitat", {})  # no schedule: no thread, records given here
    script.every = {"load_scene": 5.0}
    script.records = [("load_scene", 5.0, 7.0, ""),
                      ("load_scene", 10.0, 12.5, "load_scene: the server is not running"),
                      ("load_scene", 3.0, 4.0, "load_scene: scene 'x' failed to load")]
    t = np.arange(0.0, 12.0, 0.5)
    summary = script.summary({"t_start": t, "late": (t == 6.0).astype(np.uint8),
                              "full_render": ((t == 6.0) | (t == 9.0)).astype(np.uint8)})["load_scene"]
    assert summary["sent"] == 2 and summary["cut_by_the_end"] == 1
    assert summary["errors"] == ["load_scene: scene 'x' failed to load"]
    assert summary["reply"]["max_ms"] == 2000.0 and summary["late_frames_around"] == 1
    assert summary["full_frames_around"] == 1  # 9.0 is 2 s after the reply at 7.0


def test_every_scripted_command_has_its_option_and_a_bad_interval_is_named():
    import pytest

    from antarium.bench.loop import SCRIPTED, ScriptedCommands
    from antarium.commands.bench import add_arguments
    from antarium.server.commands import COMMANDS

    parser = argparse.ArgumentParser()
    add_arguments(parser)
    args = parser.parse_args(["loop", "--sky-every", "6", "--load-every", "30"])
    assert set(SCRIPTED) <= set(COMMANDS) and all(hasattr(args, option) for option in SCRIPTED.values())
    assert args.sky_every == 6.0 and args.load_every == 30.0 and args.edit_every is None
    with pytest.raises(ValueError, match="--sky-every must be a positive number of seconds, got -1"):
        ScriptedCommands(None, "habitat", {"sky": -1.0})
