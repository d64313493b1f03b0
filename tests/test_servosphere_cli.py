"""`antarium servosphere`: the simulated live loop, its summary and picture; bad arguments get one clear line."""

from antarium.cli import main


def test_simulated_run_prints_a_summary_and_writes_the_picture(tmp_path, capsys):
    out = tmp_path / "servo.png"
    assert main(["servosphere", "--simulate", "--seconds", "0.6", "--plot", str(out)]) == 0
    captured = capsys.readouterr()
    assert "frames 421, control loop 70" in captured.out and "error from the apex: median" in captured.out
    assert "% of the distance" in captured.out and out.stat().st_size > 10_000
    assert "\rt " in captured.err and "x real time" in captured.err  # the live status line


def test_bad_arguments_name_what_is_wrong(capsys):
    assert main(["servosphere", "--seconds", "1"]) == 2
    assert "--config" in capsys.readouterr().err
    assert main(["servosphere", "--simulate", "--seconds", "-1"]) == 2
    assert "--seconds must be a positive number" in capsys.readouterr().err
    assert main(["servosphere", "--simulate", "--seconds", "1", "--slip", "0.9"]) == 2
    assert "slip must be in [0, 0.5]" in capsys.readouterr().err
