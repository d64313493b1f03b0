"""`antarium serve` as a process: SIGINT / SIGTERM stop it after the current frame and close the trial log."""

import signal
import subprocess
import sys
import time

import h5py
import pytest

from antarium import bus
from antarium.trial_log import open_log


def _frames_on_disk(folder):
    """Frames flushed so far into the (single) trial log being written, read as a SWMR reader."""
    logs = list(folder.glob("*.h5"))
    if not logs:
        return 0
    try:
        with open_log(logs[0]) as f:
            return len(f["frames"])
    except (OSError, KeyError):  # created but not yet readable
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
