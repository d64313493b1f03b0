"""`antarium bench loop` end to end on the embedded default rig (one short run): it prints its report and writes
the same figures as JSON. No timing is asserted; the figures are the benchmark's, not the test's."""

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
