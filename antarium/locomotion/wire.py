"""Locomotion samples on the bus: a fixed little-endian struct with a version byte.

| offset | type | field     | unit / meaning                                        |
|-------:|------|-----------|-------------------------------------------------------|
| 0      | u8   | version   | 1                                                     |
| 1      | u8   | flags     | bit 0: t_device valid; other bits 0 (else refused)    |
| 2      | u16  | reserved  | 0 (else refused)                                      |
| 4      | u32  | seq       | source sequence number (wraps at 2**32)               |
| 8      | f64  | t_device  | device time, s (0 when flag bit 0 is clear)           |
| 16     | f64  | rx, ry, rz| ball rotation increment, rad, dome frame, each <= 1,000   |
| 40     | f32  | quality   | in [0, 1] (else refused)                              |

The receiver stamps `t` with its own clock on arrival: clocks of different computers are not compared.
"""

from __future__ import annotations

import math
import struct

from antarium.locomotion import BallSample

VERSION = 1
_STRUCT = struct.Struct("<BBHIddddf")
SIZE = _STRUCT.size  # 44 bytes
_FLAG_DEVICE_TIME = 0x01
#: the largest rotation increment about one axis in one sample (rad), in either sense: 160 turns of the ball, beyond
#: any tracker and any virtual ant's step (a 2 cm step on a 1 mm ball is 20 rad); a larger value is a sender's bug
MAX_ROTATION_RAD = 1000.0


class LocomotionWireError(ValueError):
    """A locomotion payload that is not a valid version-1 sample."""


def encode(sample: BallSample) -> bytes:
    flags = _FLAG_DEVICE_TIME if sample.t_device is not None else 0
    return _STRUCT.pack(
        VERSION, flags, 0, sample.seq & 0xFFFFFFFF, sample.t_device or 0.0, *sample.rotation, sample.quality
    )


def decode(payload: bytes, t: float) -> BallSample:
    """Decode a payload received at host time `t` (s)."""
    if len(payload) != SIZE:
        raise LocomotionWireError(f"locomotion payload must be {SIZE} bytes, got {len(payload)}")
    version, flags, reserved, seq, t_dev, rx, ry, rz, quality = _STRUCT.unpack(payload)
    if version != VERSION:
        raise LocomotionWireError(f"locomotion payload version {version} not supported (allowed: {VERSION})")
    if flags & ~_FLAG_DEVICE_TIME:  # a later version's meaning must not be misread as this one's
        raise LocomotionWireError(f"locomotion payload flags 0x{flags:02x} set unknown bits (allowed mask "
                                  f"0x{_FLAG_DEVICE_TIME:02x})")
    if reserved:
        raise LocomotionWireError(f"locomotion payload reserved field must be 0, got 0x{reserved:04x}")
    if not all(math.isfinite(v) for v in (t_dev, rx, ry, rz, quality)):
        raise LocomotionWireError("locomotion payload holds a non-finite number")
    if max(abs(rx), abs(ry), abs(rz)) > MAX_ROTATION_RAD:
        raise LocomotionWireError(f"locomotion payload rotation ({rx:g}, {ry:g}, {rz:g}) rad is beyond any ball's "
                                  f"motion in one sample (allowed: each within +-{MAX_ROTATION_RAD:g} rad)")
    if not 0.0 <= quality <= 1.0:
        raise LocomotionWireError(f"locomotion payload quality must be in [0, 1], got {quality:g}")
    return BallSample(t, seq, (rx, ry, rz), t_dev if flags & _FLAG_DEVICE_TIME else None, quality)
