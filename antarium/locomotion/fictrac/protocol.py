"""FicTrac (v2.1) output lines: parser and conversion to our ball frame. Field table: `docs/fictrac.md`.

A live line is "FT, " followed by 25 values joined by ", "; a `.dat` log line holds the same 25 values
without the prefix. FicTrac 2.0 wrote the first 23 of them (its `doc/data_header.txt`; no delta timestamp and
no time of day), to its log and its TCP socket alike: such a line reads with fields 24-25 NaN.
FicTrac's lab frame is +X forward, +Y right, +Z down; ours (the dome's) is +x forward, +y left, +z up: a half turn
about x, so a lab-frame rotation vector (X, Y, Z) is (X, -Y, -Z) here.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from antarium.core.numbers import is_float_text
from antarium.locomotion import BallSample

PREFIX = "FT"
N_FIELDS = 25
N_FIELDS_V20 = 23  # FicTrac 2.0's lines: fields 1..23


class FicTracParseError(ValueError):
    """A line that is not a FicTrac frame (counted and skipped by the sources)."""


class FicTracFrame(NamedTuple):
    """One FicTrac frame, in FicTrac's own frames and units (rad, ms), fields 1..25 in order."""

    frame: int
    d_rot_cam_x: float
    d_rot_cam_y: float
    d_rot_cam_z: float
    match_error: float
    d_rot_lab_x: float
    d_rot_lab_y: float
    d_rot_lab_z: float
    rot_cam_x: float
    rot_cam_y: float
    rot_cam_z: float
    rot_lab_x: float
    rot_lab_y: float
    rot_lab_z: float
    pos_x: float
    pos_y: float
    heading: float
    direction: float
    speed: float
    forward: float
    side: float
    timestamp_ms: float
    seq: int
    dt_ms: float
    time_of_day_ms: float


_INT_FIELDS = (0, 22)  # frame counter, sequence counter


def parse_line(line: str | bytes) -> FicTracFrame:
    """Parse one live ("FT, ...") or `.dat` line; raises `FicTracParseError` naming what is wrong."""
    if isinstance(line, (bytes, bytearray)):
        try:
            line = line.decode("ascii")
        except UnicodeDecodeError:
            raise FicTracParseError("FicTrac line is not ASCII text") from None
    parts = line.strip().split(",")
    if parts and parts[0].strip() == PREFIX:
        parts = parts[1:]
    if len(parts) not in (N_FIELDS, N_FIELDS_V20):
        raise FicTracParseError(f"FicTrac line must hold {N_FIELDS} comma-separated values "
                                f"({N_FIELDS_V20} from FicTrac 2.0), got {len(parts)}")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        bad = next(i for i, p in enumerate(parts) if not is_float_text(p))
        raise FicTracParseError(
            f"FicTrac field {bad + 1} ({FicTracFrame._fields[bad]}) is not a number: {parts[bad].strip()!r}"
        ) from None
    for i, v in enumerate(values):
        if not math.isfinite(v):
            raise FicTracParseError(f"FicTrac field {i + 1} ({FicTracFrame._fields[i]}) is not finite: {v}")
    for i in _INT_FIELDS:
        if values[i] != int(values[i]):
            raise FicTracParseError(f"FicTrac field {i + 1} ({FicTracFrame._fields[i]}) must be an integer, "
                                    f"got {values[i]}")
        values[i] = int(values[i])
    values += [math.nan] * (N_FIELDS - len(values))
    return FicTracFrame(*values)


def format_line(frame: FicTracFrame, prefix: bool = True) -> str:
    """The line FicTrac writes for `frame` (live with prefix, `.dat` without); inverse of `parse_line`: a frame
    whose fields 24-25 are NaN is written as FicTrac 2.0 wrote it, with 23 values."""
    values = frame[:N_FIELDS_V20] if all(math.isnan(v) for v in frame[N_FIELDS_V20:]) else frame
    body = ", ".join(repr(v) if isinstance(v, float) else str(v) for v in values)
    return f"{PREFIX}, {body}" if prefix else body


def lab_to_dome(x: float, y: float, z: float) -> tuple[float, float, float]:
    """A vector (rotation or position) from FicTrac's lab frame (+X fwd, +Y right, +Z down) to ours."""
    return (x, -y, -z)


def to_sample(frame: FicTracFrame, t: float, max_match_error: float | None = None) -> BallSample:
    """The ball rotation of one frame as a `BallSample` at host time `t` (s).

    quality = 1 - match_error / max_match_error (clipped to 0..1), or 1 when `max_match_error` is None.
    """
    rotation = lab_to_dome(frame.d_rot_lab_x, frame.d_rot_lab_y, frame.d_rot_lab_z)
    quality = 1.0
    if max_match_error is not None:
        quality = min(1.0, max(0.0, 1.0 - frame.match_error / max_match_error))
    return BallSample(t, frame.frame, rotation, frame.timestamp_ms * 1e-3, quality)
