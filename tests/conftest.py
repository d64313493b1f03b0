"""Shared helpers and fixtures: polling with a deadline, a free bus endpoint, the dome and a renderer per test
module, an isolated cache."""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import pytest


def wait_for(predicate: Callable[[], bool], timeout_s: float = 5.0, poll_s: float = 0.002) -> bool:
    """Poll `predicate` until it holds or `timeout_s` passes (tests on real time); the last answer."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return predicate()


def write_world_panorama(path: Path) -> Path:
    """A small equirectangular test world at `path` (64 x 32 PNG): a bright sky over a dark ground and one dark
    vertical band at azimuth 0..45 deg (something to steer by)."""
    import cv2
    import numpy as np

    img = np.zeros((32, 64, 3), np.uint8)
    img[:16] = 200
    img[:, :8] = 90
    cv2.imwrite(str(path), img)
    return path


def free_tcp_port(host: str = "127.0.0.1") -> int:
    """A TCP port nothing listens on now (for a bus endpoint on loopback)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def process_gone(pid: int) -> bool:
    """The process `pid` has ended (a zombie not yet reaped counts as ended)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] == "Z"
    except OSError:
        return True


@pytest.fixture(scope="module")
def dome():
    """The embedded default dome, loaded once per test module."""
    from antarium.geometry import load_dome

    return load_dome()


@pytest.fixture(scope="module")
def renderer(request, dome):
    """A renderer of `dome` at the test module's `FACE` (px a cube face, 64 where the module sets none), released
    after the module."""
    from antarium.renderers import Renderer

    r = Renderer(dome, face_size=getattr(request.module, "FACE", 64))
    yield r
    r.release()


@pytest.fixture(autouse=True)
def _no_default_log_folder_made():
    """A test's server that takes the default `[log] dir` makes ./trials in the working folder (a stray folder in
    every clone that runs the suite): the test that made it fails, and the folder goes (when it is empty)."""
    folder = Path("trials")
    existed = folder.exists()
    yield
    if not existed and folder.is_dir():
        if not any(folder.iterdir()):
            folder.rmdir()
        pytest.fail("this test made ./trials in the working folder: give its server [log] dir under tmp_path")


@pytest.fixture
def emulated_hands(monkeypatch):
    """`antarium trackball calibrate` without --emulate, the driver's USB backend replaced by the miscalibrated
    emulator and the operator's turns by the emulated ones. Returns the emulator's `faults` table of the driver
    made next (report number -> fault), for a test to fill before it runs the command."""
    from antarium.commands import trackball as command
    from antarium.locomotion.trackball import calibration
    from antarium.locomotion.trackball import driver as driver_module

    real, faults = driver_module.UsbTrackball, {}

    def driver(trackball, backend):
        emulated = calibration.miscalibrated_emulator(trackball, realtime=False)
        emulated.faults.update(faults)
        return real(trackball=trackball, backend=emulated)

    monkeypatch.setattr(driver_module, "UsbTrackball", driver)
    monkeypatch.setattr(command, "_turn_by_hand", lambda driver, axis, turns: calibration.turn_emulated(
        driver, driver.backend, axis, turns))
    return faults


@pytest.fixture
def bus_endpoint() -> str:
    """A zenoh endpoint on loopback that no other test uses."""
    return f"tcp/127.0.0.1:{free_tcp_port()}"


def pytest_configure(config) -> None:
    """Caches (the renderer's footprint matrices) go to a folder of this test run, never to ~/.cache: set before
    any fixture or child process exists, so every one of them uses it."""
    cache = Path(tempfile.mkdtemp(prefix="antarium-test-cache-"))
    os.environ["ANTARIUM_CACHE"] = str(cache)
    config.add_cleanup(lambda: shutil.rmtree(cache, ignore_errors=True))
