"""FicTrac sources against what the real program writes: video logs, tracking resets, cut lines."""

import math

import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.locomotion.fictrac.protocol import FicTracFrame, format_line
from antarium.locomotion.fictrac.timeline import replay_times

WALL_MS = 1_764_000_000_000.0   # a wall-clock time in ms since the epoch (Nov 2025)


def frame(i, t_ms, seq=None):
    values = [0.0] * 25
    values[0], values[22] = i, i if seq is None else seq
    values[6] = 0.01
    values[21] = t_ms
    values[23] = 1000 / 30
    return FicTracFrame(*values)


def video_log(n=300, fps=30.0):
    """FicTrac's log of an n-frame video: column 22 is the video position, the wall clock where that is 0."""
    t = [1000.0 * k / fps for k in range(n)]
    t[0], t[-1] = WALL_MS, WALL_MS + 10_050.0   # the first and last frames read position 0
    return [frame(k + 1, t[k]) for k in range(n)]


def write(path, frames, end="\n"):
    path.write_text("\n".join(format_line(f, prefix=False) for f in frames) + end)


def test_a_video_log_replays_in_its_own_time(tmp_path):
    path = tmp_path / "video.dat"
    write(path, video_log())
    clock = SimulatedClock()
    with open_source("fictrac-replay", path=path, clock=clock) as src:
        released = [len(src.read())]
        for _ in range(10):
            clock.advance(1.0)
            released.append(len(src.read()))
        assert src.finished
    assert released[0] == 1                          # not 298 frames at t = 0
    assert all(25 <= r <= 35 for r in released[1:])  # about 30 frames per second of the 10 s video


def test_a_video_log_gives_device_times_that_never_step_back(tmp_path):
    path = tmp_path / "video.dat"
    write(path, video_log())
    clock = SimulatedClock()
    with open_source("fictrac-replay", path=path, clock=clock) as src:
        clock.advance(20.0)
        t_dev = np.array([s.t_device for s in src.read()])
    assert len(t_dev) == 300 and np.all(np.diff(t_dev) > 0)
    assert t_dev[-1] == pytest.approx(299 / 30, abs=1e-6)


def test_live_epoch_times_are_kept_as_they_are():
    ts = [WALL_MS, WALL_MS + 5.0, WALL_MS + 2005.0, WALL_MS + 2010.0]   # a 2 s pause is real time
    assert replay_times(ts) == pytest.approx([0.0, 0.005, 2.005, 2.010])


def test_tracking_resets_are_counted_as_resets_not_gaps(tmp_path):
    # FicTrac resets tracking 5 times: column 23 goes back to 0 while column 1 keeps rising (a frame skipped).
    frames, i, seq = [], 1, 0
    for _ in range(6):
        for _ in range(20):
            frames.append(frame(i, 1000.0 + 10 * i, seq))
            i, seq = i + 1, seq + 1
        i, seq = i + 1, 0
    path = tmp_path / "resets.dat"
    write(path, frames)
    with open_source("fictrac-replay", path=path, clock=SimulatedClock()) as src:
        status = src.status()
    assert (status["resets"], status["gaps"], status["lost_frames"]) == (5, 0, 0)


def test_a_real_gap_is_still_a_gap(tmp_path):
    path = tmp_path / "gap.dat"
    write(path, [frame(1, 1000.0), frame(2, 1010.0), frame(5, 1040.0)])
    with open_source("fictrac-replay", path=path, clock=SimulatedClock()) as src:
        status = src.status()
    assert (status["resets"], status["gaps"], status["lost_frames"]) == (0, 1, 2)


def test_a_last_line_cut_inside_its_last_field_is_refused(tmp_path):
    text = "".join(format_line(frame(i, 1000.0 + 10 * i), prefix=False) + "\n" for i in range(1, 4))
    full = format_line(frame(4, 1040.0)._replace(time_of_day_ms=43_200_123.456), prefix=False)
    path = tmp_path / "cut.dat"
    path.write_text(text + full[:-5])   # the writer stopped inside field 25
    clock = SimulatedClock()
    with open_source("fictrac-replay", path=path, clock=clock) as src:
        clock.advance(1.0)
        got = src.read()
        status = src.status()
    assert [s.seq for s in got] == [1, 2, 3]
    assert status["malformed"] == 1 and "cut short" in status["last_error"]
    assert math.isfinite(got[-1].t_device)


def test_the_docs_say_which_fictrac_speaks_tcp():
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "fictrac.md").read_text()
    assert "FicTrac 2.1 sends **UDP only**" in text and '`transport = "tcp"` fits the 2.0 releases' in text
    assert "cannot disagree" not in text


def test_the_docs_name_functions_that_exist():
    import importlib
    import re
    from pathlib import Path

    text = (Path(__file__).parents[1] / "docs" / "fictrac.md").read_text()
    names = set(re.findall(r"`([a-z_]+(?:\.[A-Za-z_]+)+)", text))  # lower case: modules and their functions
    assert {"antarium.core.ball.arc_step", "antarium.locomotion.fictrac.timeline.replay_times"} <= names
    for name in names:
        module, _, attr = name.rpartition(".")
        assert name.startswith("antarium.") and hasattr(importlib.import_module(module), attr), name


def test_a_live_datagram_cut_inside_its_last_field_is_counted(tmp_path):
    import socket
    import time

    with open_source("fictrac", port=0) as src:
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as tx:
            whole = [format_line(frame(i, 1000.0 + 10 * i)) + "\n" for i in (1, 2)]
            cut = format_line(frame(3, 1030.0)._replace(time_of_day_ms=43_200_123.456))[:-5]
            for text in (*whole, cut):
                tx.sendto(text.encode(), src.address)
        deadline = time.monotonic() + 5.0
        while src.status()["lines"] < 3:
            assert time.monotonic() < deadline
            time.sleep(0.005)
        status = src.status()
        got = src.read()
    assert [s.seq for s in got] == [1, 2]
    assert status["malformed"] == 1 and "cut short" in status["last_error"]
