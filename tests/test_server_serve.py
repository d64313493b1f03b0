"""`antarium serve` as a process: SIGINT / SIGTERM stop it after the current frame and close the trial log."""

import os
import signal
import subprocess
import sys
import time

import h5py
import pytest

from antarium import bus
from antarium.trial_log import LogError, open_log


def _frames_on_disk(folder):
    """Frames flushed so far into the (single) trial log being written, read as a SWMR reader."""
    logs = list(folder.glob("*.h5"))
    if not logs:
        return 0
    try:
        with open_log(logs[0]) as f:
            return len(f["frames"])
    except (OSError, KeyError, LogError):  # created but not yet readable (caught mid-creation: 'truncated file')
        return 0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_closes_the_trial_log_cleanly(tmp_path, sig):
    config = tmp_path / "rig.toml"
    config.write_text(f"""
[rig]
name = "tserve"
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
[render]
scene = "horizon"
face_size = 64
[link]
interface = "virtual"
[log]
dir = "{tmp_path / 'logs'}"
flush_s = 0.2
""")
    proc = subprocess.Popen([sys.executable, "-m", "antarium", "serve", "--config", str(config), "--record", "sig"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while _frames_on_disk(tmp_path / "logs") < 20 and time.monotonic() < deadline:
            time.sleep(0.1)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "stopping after this frame" in err and "trial log" in out
    (path,) = (tmp_path / "logs").glob("*.h5")
    with h5py.File(path, "r") as f:  # a plain open works: the file was closed, not left for SWMR recovery
        assert len(f["frames"]) >= 20
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert kinds[-1] == "trial_stopped"


def _config(tmp_path, rig, link='interface = "virtual"'):
    config = tmp_path / "rig.toml"
    config.write_text(f"""
[rig]
name = "{rig}"
[bus]
listen = ["{bus.free_tcp_endpoint()}"]
[render]
scene = "horizon"
face_size = 64
far_layer = "off"
[link]
{link}
[log]
dir = "{tmp_path / 'logs'}"
flush_s = 0.2
""")
    return config


def _serve(config, *args):
    """`antarium serve` in a process group of its own (a Ctrl-C at a terminal reaches the whole group)."""
    return subprocess.Popen([sys.executable, "-m", "antarium", "serve", "--config", str(config), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def test_a_signal_during_start_up_leaves_no_empty_trial_log(tmp_path):
    proc = _serve(_config(tmp_path, "tserve_start"), "--record", "early")
    try:
        assert "antarium serve: rig 'tserve_start'" in proc.stdout.readline()  # printed before the start-up
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "Traceback" not in err
    for path in (tmp_path / "logs").glob("*.h5"):  # (none when the signal came before the first frame)
        with h5py.File(path, "r") as f:
            assert len(f["frames"]) > 0, f"{path.name}: a trial log without a frame was left"


def test_ctrl_c_prints_no_alarm_about_the_emulator_it_stops(tmp_path):
    """Ctrl-C reaches the spawned emulator too: its end is the shutdown, not an alarm."""
    config = _config(tmp_path, "tserve_alarm", 'interface = "udp"\nhost = "127.0.0.1"\nport = 0\nspawn_emulator = true')
    proc = _serve(config, "--status-every", "0.1")
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line or " frames, " in line and "latency p50" in line:  # frames are running
                break
        os.killpg(proc.pid, signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 0, err
    assert "stopping after this frame" in err
    assert "ALARM" not in out, out


@pytest.mark.parametrize("args, message", [
    (["--record", "", "--seconds", "2"], "--record needs a trial name"),
    (["--record", "  ", "--seconds", "1"], "--record needs a trial name"),
    (["--status-every", "-3", "--seconds", "1"], "--status-every must be a number of seconds >= 0"),
    (["--status-every", "nan", "--seconds", "1"], "(0: no status lines), got nan"),
])
def test_bad_record_and_status_every_are_refused_in_one_line(tmp_path, capsys, args, message):
    from antarium.cli import main

    assert main(["serve", "--config", str(_config(tmp_path, "tserve_bad")), *args]) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.strip().splitlines()) == 1 and message in captured.err
    assert not (tmp_path / "logs").exists() or not list((tmp_path / "logs").iterdir())
