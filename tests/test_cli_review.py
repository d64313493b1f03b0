"""Careless input a new user types (review of the command line): an option that does not apply to what the command
was asked to do, or a value no picture, port or disk can have, is refused in one line naming the option and what is
allowed, before any work, instead of being ignored or failing deep inside a library."""

from __future__ import annotations

import pytest

from antarium.cli import main


def _refused(capsys, argv: list[str]) -> str:
    """The one error line of `antarium ARGV`, which must do no work and write nothing."""
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"antarium {argv[0]}: error: "), err
    assert out == ""
    return lines[0]


@pytest.mark.parametrize(("argv", "option", "applies"), [
    (["--source", "fictrac", "--path", "x.dat"], "--path", "--source fictrac-replay"),
    (["--source", "fictrac-replay", "--path", "x.dat", "--port", "5001"], "--port", "--source fictrac"),
    (["--emulate", "--host", "10.0.0.1"], "--host", "--source fictrac"),
    (["--emulate", "--transport", "tcp"], "--transport", "--source fictrac"),
    (["--emulate", "--turns", "5"], "--turns", "calibrate"),
    (["--emulate", "--axes", "x"], "--axes", "calibrate"),
    (["--emulate", "--dry-run"], "--dry-run", "calibrate"),
    (["--source", "fictrac", "--replug-after", "2"], "--replug-after", "--emulate"),
    (["--unplug-at", "2"], "--unplug-at", "--emulate"),
])
def test_trackball_refuses_an_option_that_does_not_apply(argv, option, applies, tmp_path, monkeypatch, capsys):
    """`trackball --source fictrac --path x.dat` listened on UDP 5000 and ignored the file; `--turns 5` without
    calibrate ran the trackball: an option given where it does nothing is refused, naming where it applies."""
    monkeypatch.chdir(tmp_path)
    line = _refused(capsys, ["trackball", *argv, "--no-bus", "--seconds", "0.2"])
    assert option in line and applies in line


def test_trackball_defaults_still_apply(tmp_path, monkeypatch, capsys):
    """The options left out keep their stated defaults (FicTrac UDP 127.0.0.1:5000, axes z,x,y, 3 turns)."""
    monkeypatch.chdir(tmp_path)
    assert main(["trackball", "--source", "fictrac", "--no-bus", "--seconds", "0.2"]) == 2
    _, err = capsys.readouterr()
    assert "udp 127.0.0.1:5000" in err


def test_monitor_port_names_the_option(tmp_path, monkeypatch, capsys):
    """`monitor --port -5` was refused as `[monitor] port must be ...`, a config key the user never wrote."""
    monkeypatch.chdir(tmp_path)
    line = _refused(capsys, ["monitor", "--port", "-5"])
    assert "--port" in line and "65535" in line


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_check_min_free_gb_must_be_a_size(value, tmp_path, monkeypatch, capsys):
    """`check --min-free-gb -1` passed the disk check and `inf` failed it whatever the disk: refused at the start."""
    monkeypatch.chdir(tmp_path)
    line = _refused(capsys, ["check", "--auto", "--min-free-gb", value])
    assert "--min-free-gb" in line and ">= 0" in line


def test_render_width_has_an_upper_bound(tmp_path, monkeypatch, capsys):
    """`render --width 99999999` rendered, then failed inside the image library ("Image size of 99999999x60332802
    pixels is too large"), not naming --width: refused at the start with the allowed range."""
    monkeypatch.chdir(tmp_path)
    line = _refused(capsys, ["render", "grating", "--width", "99999999"])
    assert "--width" in line and "at most" in line
    assert list(tmp_path.iterdir()) == []


def test_layout_out_with_no_pictures_is_refused(tmp_path, monkeypatch, capsys):
    """`layout --no-pictures --out figs` printed the summary and ignored --out: the two exclude each other."""
    monkeypatch.chdir(tmp_path)
    line = _refused(capsys, ["layout", "--no-pictures", "--out", "figs"])
    assert "--out" in line and "--no-pictures" in line
    assert list(tmp_path.iterdir()) == []


def test_trackball_ctrl_c_ends_the_run_with_its_final_status(tmp_path):
    """Ctrl-C is how `antarium trackball` (no --seconds: "until Ctrl-C") ends, yet it ended as an interruption:
    exit status 130 and no `trackball final` line. Now the run ends normally, its final status printed."""
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, "-m", "antarium", "trackball", "--emulate", "--no-bus"], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        while "trackball status" not in proc.stdout.readline():  # running: the first status line is out
            assert proc.poll() is None, proc.stderr.read()
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "trackball final: " in out and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []


def test_layout_reports_absolute_paths(tmp_path, monkeypatch, capsys):
    """`layout --export t.csv` printed `per-LED table: t.csv` (and `scene`, `layout --regenerate` their relative
    names): every path a command reports is absolute."""
    monkeypatch.chdir(tmp_path)
    assert main(["layout", "--export", "t.csv"]) == 0
    out = capsys.readouterr().out
    assert f"per-LED table: {tmp_path / 't.csv'}" in out
    assert [p.name for p in tmp_path.iterdir()] == ["t.csv"]
