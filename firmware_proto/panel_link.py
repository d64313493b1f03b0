"""The distributor <-> panel serial link of each pentagon (10 Mbit/s, Manchester-coded, 10BASE-T-like).

A frame on the line, in transmission order (every byte least-significant bit first):

    PREAMBLE  7 x 0x55
    SYNC      0xD5
    TYPE/DEST bits 7-4 = frame type, bits 3-0 = slot 0..4 in the pentagon (0xF = all five)
    INFO      frame sequence/flags (VIDEO, LATCH), else 0
    DATA      length fixed by the type (SERIAL_DATA_SIZE)
    CRC       CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0) over TYPE/DEST..DATA,
              sent high byte first

Manchester (IEEE 802.3 convention): bit 0 = high then low (half-bit symbols 1, 0), bit 1 = low then high (0, 1);
20 M half-bit symbols per second. A line capture is a uint8 array of symbols 0/1; a frame ends where the line
goes idle (the end of the array).

`to_line`/`from_line` are the bit-exact path; `check_serial_frame` is the fast path's check, and both accept and
reject exactly the same frames (the tests show it).
"""

from __future__ import annotations

import binascii
from typing import NamedTuple

import numpy as np

from antarium.geometry.constants import LEDS_PER_PANEL, N_ACTUATORS, PANELS_PER_PENTAGON

from .config import MAX_PERCENT
from .errors import (
    CrcError,
    FieldRangeError,
    FramingError,
    LengthError,
    ManchesterError,
    PanelError,
    UnknownTypeError,
)
from .fields import Field, FieldTable
from .video import PANEL_DATA_SIZE

PREAMBLE = b"\x55" * 7
SYNC = 0xD5
CRC_INIT = 0xFFFF
BIT_RATE_HZ = 10_000_000

ST_VIDEO = 0x0
ST_LATCH = 0x1
ST_POLARISER = 0x2
ST_DOT_CORRECTION = 0x3
ST_BRIGHTNESS = 0x4
ST_STATUS_POLL = 0x5
ST_PANEL_STATUS = 0x8  # upstream: panel -> distributor, slot = source
SLOT_ALL = 0xF

FAULT_BITMAP_BYTES = (LEDS_PER_PANEL + 7) // 8  # 93

#: PANEL_STATUS data, the answer to STATUS_POLL; fault bitmaps and the holding bits follow this table
PANEL_STATUS_HEAD = FieldTable(
    "PANEL_STATUS",
    (
        Field("temperature_cc", "h", -32768, 32767),  # 0.01 degC
        Field("current_ma", "H", 0, 0xFFFF),           # LED supply current
        Field("holding", "H", 0, (1 << N_ACTUATORS) - 1),  # bit j = actuator j on holding current
    ),
)

#: frame type -> (data bytes, slot rule: "one" = a slot 0..4, "all" = SLOT_ALL only, "any" = either)
SERIAL_TYPES = {
    ST_VIDEO: (PANEL_DATA_SIZE, "one"),
    ST_LATCH: (0, "all"),
    ST_POLARISER: (2 * N_ACTUATORS, "one"),
    ST_DOT_CORRECTION: (LEDS_PER_PANEL, "one"),
    ST_BRIGHTNESS: (1, "all"),
    ST_STATUS_POLL: (0, "one"),
    ST_PANEL_STATUS: (PANEL_STATUS_HEAD.size + 2 * FAULT_BITMAP_BYTES + 2 * N_ACTUATORS, "one"),
}
#: frame types whose data are percentages 0..100 (a panel refuses more, as the distributor does)
PERCENT_TYPES = (ST_DOT_CORRECTION, ST_BRIGHTNESS)
OVERHEAD_BYTES = len(PREAMBLE) + 1 + 2 + 2  # preamble, sync, type/dest + info, CRC


class SerialFrame(NamedTuple):
    ftype: int
    slot: int
    info: int
    data: bytes


def crc16(data) -> int:
    """CRC-16/CCITT-FALSE of `data` (check value of b'123456789' is 0x29B1)."""
    return binascii.crc_hqx(data, CRC_INIT)


def check_serial_frame(frame: SerialFrame) -> SerialFrame:
    """`frame` if its type, slot, info and data length are valid, else a ProtocolError subclass."""
    spec = SERIAL_TYPES.get(frame.ftype)
    if spec is None:
        raise UnknownTypeError(f"serial frame type 0x{frame.ftype:x} unknown: allowed {sorted(SERIAL_TYPES)}")
    size, rule = spec
    if len(frame.data) != size:
        raise LengthError(f"serial frame type 0x{frame.ftype:x} needs {size} data bytes, got {len(frame.data)}")
    one = 0 <= frame.slot < PANELS_PER_PENTAGON
    if not {"one": one, "all": frame.slot == SLOT_ALL, "any": one or frame.slot == SLOT_ALL}[rule]:
        raise PanelError(f"serial frame type 0x{frame.ftype:x}: slot {frame.slot} not allowed ({rule})")
    if not 0 <= frame.info <= 0xFF:
        raise FramingError(f"serial INFO byte {frame.info} out of range 0..255")
    if frame.ftype in PERCENT_TYPES and frame.data and max(frame.data) > MAX_PERCENT:
        i = next(k for k, v in enumerate(frame.data) if v > MAX_PERCENT)
        raise FieldRangeError(f"serial frame type 0x{frame.ftype:x}: percent entry {i} is {frame.data[i]}: "
                              f"allowed 0..{MAX_PERCENT}")
    return frame


def to_bytes(frame: SerialFrame) -> bytes:
    """The bytes of a checked frame on the line: preamble, sync, type/dest, info, data, CRC."""
    check_serial_frame(frame)
    body = bytes(((frame.ftype << 4) | frame.slot, frame.info)) + bytes(frame.data)
    return PREAMBLE + bytes((SYNC,)) + body + crc16(body).to_bytes(2, "big")


def from_bytes(raw) -> SerialFrame:
    """Line bytes -> the checked SerialFrame. Raises FramingError, CrcError and the `check_serial_frame` errors."""
    raw = bytes(raw)
    start = len(PREAMBLE) + 1
    if len(raw) < start + 4 or raw[:len(PREAMBLE)] != PREAMBLE or raw[len(PREAMBLE)] != SYNC:
        raise FramingError(f"serial frame of {len(raw)} bytes lacks the 7 x 0x55 preamble, 0xD5 sync and a header")
    body, crc = raw[start:-2], int.from_bytes(raw[-2:], "big")
    if crc16(body) != crc:
        raise CrcError(f"serial frame CRC 0x{crc:04x} does not match its contents (0x{crc16(body):04x})")
    return check_serial_frame(SerialFrame(body[0] >> 4, body[0] & 0x0F, body[1], body[2:]))


def manchester_encode(raw) -> np.ndarray:
    """Bytes -> Manchester half-bit symbols (uint8 0/1, 16 per byte), LSB first, 0 = (1, 0), 1 = (0, 1)."""
    bits = np.unpackbits(np.frombuffer(bytes(raw), np.uint8), bitorder="little")
    symbols = np.empty(2 * bits.size, np.uint8)
    symbols[0::2] = 1 - bits
    symbols[1::2] = bits
    return symbols


def manchester_decode(symbols) -> bytes:
    """Half-bit symbols -> bytes. Raises ManchesterError (a pair without a mid-bit transition) or FramingError."""
    s = np.asarray(symbols)
    if s.ndim != 1 or s.size % 16:
        raise FramingError(f"a line capture must hold a whole number of bytes (16 symbols each), got {s.size}")
    if s.size and (s.max() > 1):
        raise ManchesterError(f"line symbols must be 0 or 1, got {int(s.max())}")
    first, second = s[0::2], s[1::2]
    bad = first == second
    if bad.any():
        i = int(np.argmax(bad))
        raise ManchesterError(f"Manchester violation at bit {i}: symbols {int(first[i])}{int(second[i])}")
    return np.packbits(second.astype(np.uint8), bitorder="little").tobytes()


def to_line(frame: SerialFrame) -> np.ndarray:
    """A frame as the half-bit symbols the distributor's FPGA drives onto the pentagon link."""
    return manchester_encode(to_bytes(frame))


def from_line(symbols) -> SerialFrame:
    """Half-bit symbols received by a panel -> the checked frame (any ProtocolError subclass on bad input)."""
    return from_bytes(manchester_decode(symbols))


def line_time_s(frame: SerialFrame) -> float:
    """Seconds a frame occupies the 10 Mbit/s link."""
    return (OVERHEAD_BYTES + len(frame.data)) * 8 / BIT_RATE_HZ
