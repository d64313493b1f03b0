"""`antarium serve` as a process: SIGINT / SIGTERM stop it after the current frame and close the trial log."""

import signal
import subprocess
import sys
import time

import h5py
import pytest

from antarium import bus


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
        deadline = time.monotonic() + 30
        while not list((tmp_path / "logs").glob("*.h5")) and time.monotonic() < deadline:
            time.sleep(0.1)
        time.sleep(1.0)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert "stopping after this frame" in err and "trial log" in out
    (path,) = (tmp_path / "logs").glob("*.h5")
    with h5py.File(path, "r") as f:  # a plain open works: the file was closed, not left for SWMR recovery
        assert len(f["frames"]) > 50
        kinds = [k.decode() for k in f["events"]["kind"]]
        assert kinds[-1] == "trial_stopped"
