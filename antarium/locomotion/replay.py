"""Replay ball rotations from an earlier trial log (HDF5, table `locomotion`) or a CSV file.

A CSV file has a header row naming at least `t, rx, ry, rz` (seconds; radians about the dome axes),
optionally `seq`, `t_device`, `quality`. Samples come out at their recorded time offsets on the injected
clock, with their recorded sequence numbers: offsets from the trial's own start for a trial log (its first
frame's `t_start`, when the original loop first read its source), so a replayed trial drives the loop exactly
as the original did (a source that delivered its first sample 2 s into the trial does so in the replay too).
A CSV file (or a trial log without frames) knows no trial start: its first sample comes at `start()`, the
others at their offsets from it. Looped, each lap's sequence
numbers are the recorded ones + lap x (largest - smallest recorded + 1): gaps recur, numbers never repeat; a lap
lasts the recording's span plus its median step, so a recording whose samples are all due at one time cannot be
looped (refused).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from antarium.core.clock import Clock, MonotonicClock
from antarium.core.numbers import as_real
from antarium.locomotion import BallSample, LocomotionSource

#: the fastest a recording is played back, times its recorded pace
MAX_SPEED = 1000.0


def check_speed(source: str, speed: Any) -> float:
    """A replay's `speed` (times the recorded pace; 1 = real time) as a float: a finite real number in
    (0, MAX_SPEED], else one ValueError naming the `source` ("replay", "fictrac-replay"), the value and the range."""
    number = as_real(speed)
    if not 0 < number <= MAX_SPEED:
        raise ValueError(f"{source} speed must be a finite number in (0, {MAX_SPEED:g}] (1 = real time), "
                         f"got {repr(speed)[:60]}")
    return number


def trial_start(path: str | Path) -> float | None:
    """The start of the trial a trial log recorded (its first frame's `t_start`, on the loop's clock), or None
    for a CSV file or a log without frames."""
    from antarium.trial_log import open_log

    path = Path(path)
    if path.suffix.lower() not in (".h5", ".hdf5"):
        return None
    with open_log(path) as f:
        if "frames" not in f or len(f["frames"]) == 0:
            return None
        t = float(f["frames"][0]["t_start"])
    return t if math.isfinite(t) else None


def load_samples(path: str | Path) -> np.ndarray:
    """The recorded samples as a structured array with fields t, seq, rx, ry, rz, t_device, quality."""
    from antarium.trial_log import SAMPLE_DTYPE, LogError, open_log

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"replay file {str(path)!r} does not exist")
    if path.suffix.lower() in (".h5", ".hdf5"):
        try:
            f = open_log(path)
        except LogError as exc:  # cut short, or not a trial log: a bad replay file like any other
            raise ValueError(f"replay file: {exc}") from None
        with f:
            if "locomotion" not in f:
                raise ValueError(f"{str(path)!r} has no 'locomotion' table; is it an antarium trial log?")
            data = f["locomotion"][:].astype(SAMPLE_DTYPE)
        return _finite(data, f"replay file {str(path)!r} locomotion table row", range(len(data)))
    if path.suffix.lower() != ".csv":
        raise ValueError(f"replay file {str(path)!r} must be .h5/.hdf5 (trial log) or .csv")
    rows, lines = [], []
    try:
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            missing = {"t", "rx", "ry", "rz"} - set(reader.fieldnames or ())
            if missing:
                raise ValueError(f"replay CSV {str(path)!r} lacks columns {sorted(missing)}; needs t, rx, ry, rz")
            for i, row in enumerate(reader):
                lines.append(reader.line_num)  # blank lines are skipped: count the file's lines
                short = [k for k in reader.fieldnames if row[k] is None]
                if short:
                    raise ValueError(f"replay CSV {str(path)!r} line {reader.line_num}: columns {short} are missing "
                                     "(a row cut short?)")
                try:
                    rows.append((float(row["t"]), int(row.get("seq") or i), float(row["rx"]), float(row["ry"]),
                                 float(row["rz"]), float(row.get("t_device") or "nan"),
                                 float(row.get("quality") or 1.0)))
                except ValueError as exc:
                    raise ValueError(f"replay CSV {str(path)!r} line {reader.line_num}: {exc}") from None
    except UnicodeDecodeError as exc:
        raise ValueError(f"replay CSV {str(path)!r} is not UTF-8 text ({exc.reason} at byte {exc.start}); "
                         "a replay file is a trial log (.h5) or a CSV file") from None
    return _finite(np.array(rows, dtype=SAMPLE_DTYPE), f"replay CSV {str(path)!r} line", lines)


#: a sample due within this many seconds after now is due now: a recorded time rounded just past the reading
#: that took it (the scripted source's tolerance) comes in the same frame as in the original
DUE_EPS_S = 1e-12

#: columns that must hold finite numbers (t is checked with its order by `ReplaySource`; t_device may be nan: none)
FINITE_COLUMNS = ("rx", "ry", "rz", "quality")


def _finite(data: np.ndarray, where: str, numbers: Sequence[int]) -> np.ndarray:
    """`data`, or ValueError naming the first sample with a non-finite `FINITE_COLUMNS` value: `where` then its
    number in `numbers` (each sample's row or line of the file), the column and the value."""
    bad = ~np.column_stack([np.isfinite(data[c]) for c in FINITE_COLUMNS])
    if bad.any():
        i, j = np.argwhere(bad)[0]
        column = FINITE_COLUMNS[j]
        raise ValueError(f"{where} {numbers[i]}: {column} must be a finite number, got {data[column][i]}")
    return data


class ReplaySource(LocomotionSource):
    """Play back recorded samples (`path`: trial log or CSV) at `speed` times the recorded pace."""

    def __init__(self, path: str, speed: float = 1.0, loop: bool = False, clock: Clock | None = None) -> None:
        speed = check_speed("replay", speed)
        self.data = load_samples(path)
        if len(self.data) == 0:
            raise ValueError(f"replay file {path!r} holds no samples")
        if not np.all(np.isfinite(self.data["t"])) or np.any(np.diff(self.data["t"]) < 0):
            raise ValueError(f"replay file {path!r}: sample times must be finite and non-decreasing")
        self.speed, self.loop = speed, bool(loop)
        self.clock = clock or MonotonicClock()
        start = trial_start(path)
        anchor = self.data["t"][0] if start is None else start
        # a sample read by the original's first frame (arrived before the trial's start) comes at start() too
        self._offsets = np.maximum(self.data["t"] - anchor, 0.0) / self.speed
        self._span = float(self._offsets[-1]) + (float(np.median(np.diff(self._offsets))) if len(self.data) > 1
                                                  else 1.0)
        if self.loop and self._span <= 0:  # every lap would be due at once: read() would never return
            raise ValueError(f"replay file {path!r}: all {len(self.data)} samples are due at one time "
                             f"(t = {float(self.data['t'][0]):g} s), so it cannot be looped; replay it once "
                             "(loop = false)")
        seqs = self.data["seq"]
        self._lap_seq = int(seqs.max()) - int(seqs.min()) + 1  # a lap's sequence numbers follow the previous lap's
        self._t0: float | None = None
        self._i = 0
        self._lap = 0

    def start(self) -> None:
        self._t0 = self.clock.now()
        self._i = 0
        self._lap = 0

    @property
    def finished(self) -> bool:
        return not self.loop and self._i >= len(self.data)

    def read(self) -> list[BallSample]:
        if self._t0 is None:
            self.start()
        now = self.clock.now() - self._t0 + DUE_EPS_S
        out = []
        n = len(self.data)
        while True:
            if self._i >= n:
                if not self.loop:
                    break
                self._i, self._lap = 0, self._lap + 1
            t_rel = self._offsets[self._i] + self._lap * self._span
            if t_rel > now:
                break
            row = self.data[self._i]
            t_dev = None if math.isnan(row["t_device"]) else float(row["t_device"])
            seq = int(row["seq"]) + self._lap * self._lap_seq
            out.append(BallSample(self._t0 + float(t_rel), seq, (float(row["rx"]), float(row["ry"]),
                                                                 float(row["rz"])), t_dev, float(row["quality"])))
            self._i += 1
        return out

    def status(self) -> dict[str, Any]:
        return {"connected": True, "replayed": self._i + self._lap * len(self.data), "total": len(self.data),
                "finished": self.finished}
