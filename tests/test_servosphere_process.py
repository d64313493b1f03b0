"""On the wall clock the servosphere's loop runs in a process of its own; samples, log rows and status come back."""

import time

import numpy as np
import pytest

from antarium.locomotion import open_source
from antarium.locomotion.servosphere.process import ServosphereProcess


class Rows(list):
    add_servosphere = list.append


def test_the_loop_runs_in_its_own_process_and_hands_everything_back():
    src = open_source("servosphere", simulation={"seed": 2, "speed": 0.05})
    assert isinstance(src, ServosphereProcess)
    rows = Rows()
    src.use_log(rows)
    t_start = time.monotonic()
    src.start()
    try:
        deadline = time.monotonic() + 20.0  # 700 frames a second unless the machine is overloaded
        while src.status()["frames"] < 200 and time.monotonic() < deadline:
            time.sleep(0.05)
        samples = src.read()
        status = src.status()
    finally:
        src.stop()
    assert status["connected"] and status["frames"] >= 200
    assert len(samples) > 50
    assert all(a.seq < b.seq and a.t <= b.t for a, b in zip(samples[:-1], samples[1:], strict=True))
    assert t_start <= samples[0].t and samples[-1].t <= time.monotonic()  # the frame loop's clock
    assert np.linalg.norm(np.sum([s.rotation for s in samples], axis=0)) > 0.01  # rad: the ball turned
    assert len(rows) >= status["frames"] - 10 and rows[-1][1] >= status["frames"]
    assert src.status()["connected"] is False


def test_start_failures_and_unknown_options_are_one_clear_line():
    with pytest.raises(RuntimeError, match="slip must be in"):
        open_source("servosphere", simulation={"slip": 0.9}).start()
    with pytest.raises(TypeError, match="speed"):
        open_source("servosphere", speed=0.05)
