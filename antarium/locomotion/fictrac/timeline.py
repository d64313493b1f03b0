"""Replay times of a FicTrac log from its column 22, which holds one of two clocks.

Live, column 22 is the camera time in ms since the epoch. From a video it is the position in the video (ms
from its start), except where that position reads 0 (FicTrac then writes the wall-clock time instead: the
first frame, and the last). A step between frames of different clocks, or a step back, says nothing about
the time between them: it is replaced by the median of the log's meaningful steps.
"""

from __future__ import annotations

import numpy as np

#: column 22 values from this many ms up are epoch times (1e11 ms is March 1973); below, video positions
EPOCH_MIN_MS = 1e11


def replay_times(timestamps_ms) -> np.ndarray:
    """(N,) column-22 values (ms) -> (N,) float64 seconds from the first frame, never decreasing."""
    ts = np.asarray(timestamps_ms, dtype=np.float64)
    if len(ts) == 0:
        return np.zeros(0)
    epoch = ts >= EPOCH_MIN_MS
    steps = np.diff(ts)
    good = (epoch[1:] == epoch[:-1]) & (steps >= 0)
    fill = float(np.median(steps[good])) if good.any() else 0.0
    steps = np.where(good, steps, fill)
    return np.concatenate([[0.0], np.cumsum(steps) * 1e-3])
