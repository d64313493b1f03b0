"""The pentagon serial link: framing, CRC-16/CCITT-FALSE, Manchester coding, bit-exact vs fast path."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.firmware_proto import panel_link as pl
from antarium.firmware_proto.errors import (
    CrcError,
    FramingError,
    LengthError,
    ManchesterError,
    PanelError,
    ProtocolError,
    UnknownTypeError,
)


def crc16_bitwise(data: bytes) -> int:
    """Reference CRC-16/CCITT-FALSE, one bit at a time (poly 0x1021, init 0xFFFF, MSB first, no xorout)."""
    crc = 0xFFFF
    for byte in data:
        crc ^= byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


def frames():
    """Any valid serial frame."""
    def build(ftype, slot, info, data):
        size, rule = pl.SERIAL_TYPES[ftype]
        slot = pl.SLOT_ALL if rule == "all" else slot
        data = data[:size].ljust(size, b"\0")
        if ftype in pl.PERCENT_TYPES:  # percentages 0..100
            data = bytes(b % 101 for b in data)
        return pl.SerialFrame(ftype, slot, info, data)
    return st.builds(build, st.sampled_from(sorted(pl.SERIAL_TYPES)), st.integers(0, 4), st.integers(0, 255),
                     st.binary(min_size=0, max_size=1110))


def test_crc_check_value_and_reference():
    assert pl.crc16(b"123456789") == 0x29B1
    rng = np.random.default_rng(0)
    for n in (0, 1, 2, 17, 1112):
        data = rng.integers(0, 256, n, dtype=np.uint8).tobytes()
        assert pl.crc16(data) == crc16_bitwise(data)


def test_golden_latch_frame():
    f = pl.SerialFrame(pl.ST_LATCH, pl.SLOT_ALL, 5, b"")
    assert pl.to_bytes(f) == bytes.fromhex("55 55 55 55 55 55 55 d5 1f 05 5e e7")
    assert crc16_bitwise(bytes.fromhex("1f 05")) == 0x5EE7
    line = "".join(map(str, pl.to_line(f)))
    assert line[:32] == "0110011001100110" * 2
    assert line[112:] == "0110011001100101" + "0101010101101010011001101010101010010101011001100101011010010101"
    assert pl.line_time_s(f) == pytest.approx(12 * 8 / 10e6)


def test_manchester_convention():
    # IEEE 802.3: 0 = high then low, 1 = low then high; bytes LSB first
    assert "".join(map(str, pl.manchester_encode(b"\x01"))) == "01" + "10" * 7
    assert pl.manchester_decode(pl.manchester_encode(bytes(range(256)))) == bytes(range(256))


@settings(max_examples=400, deadline=None)
@given(frames())
def test_round_trip_every_type(frame):
    assert pl.from_line(pl.to_line(frame)) == frame
    assert pl.check_serial_frame(frame) == frame


@settings(max_examples=300, deadline=None)
@given(frames(), st.integers(0, 10**6))
def test_single_symbol_error_is_a_manchester_violation(frame, where):
    symbols = pl.to_line(frame)
    symbols[where % symbols.size] ^= 1
    with pytest.raises(ManchesterError, match="violation"):
        pl.from_line(symbols)


@settings(max_examples=300, deadline=None)
@given(frames(), st.integers(0, 10**6))
def test_inverted_bit_after_sync_fails_the_crc(frame, where):
    symbols = pl.to_line(frame)
    bit = 64 + where % (symbols.size // 2 - 64)  # a bit after preamble and sync
    symbols[2 * bit:2 * bit + 2] ^= 1          # still valid Manchester, wrong bit
    with pytest.raises(CrcError):
        pl.from_line(symbols)


def test_framing_errors():
    good = pl.to_line(pl.SerialFrame(pl.ST_LATCH, pl.SLOT_ALL, 1, b""))
    with pytest.raises(FramingError, match="whole number"):
        pl.from_line(good[:-1])
    with pytest.raises(FramingError, match="whole number"):
        pl.from_line(good[:-2])
    bad_preamble = good.copy()
    bad_preamble[0:2] ^= 1
    with pytest.raises(FramingError, match="preamble"):
        pl.from_line(bad_preamble)
    with pytest.raises(FramingError):
        pl.from_line(np.zeros(0, np.uint8))
    with pytest.raises(ManchesterError):
        pl.from_line(np.full(16 * 12, 2, np.uint8))


def test_frame_check_errors_are_typed():
    with pytest.raises(UnknownTypeError):
        pl.check_serial_frame(pl.SerialFrame(0x7, 0, 0, b""))
    with pytest.raises(LengthError, match="1110 data bytes"):
        pl.check_serial_frame(pl.SerialFrame(pl.ST_VIDEO, 0, 0, b"\0" * 1109))
    with pytest.raises(PanelError):
        pl.check_serial_frame(pl.SerialFrame(pl.ST_VIDEO, 5, 0, b"\0" * 1110))
    with pytest.raises(PanelError):
        pl.check_serial_frame(pl.SerialFrame(pl.ST_LATCH, 0, 0, b""))
    # the same rejections on the bit-exact path, after a valid CRC
    body = bytes([(pl.ST_VIDEO << 4) | 5, 0]) + b"\0" * 1110
    raw = pl.PREAMBLE + bytes([pl.SYNC]) + body + pl.crc16(body).to_bytes(2, "big")
    with pytest.raises(PanelError):
        pl.from_line(pl.manchester_encode(raw))


@settings(max_examples=500, deadline=None)
@given(st.integers(0, 15), st.integers(0, 15), st.integers(0, 255), st.binary(max_size=1200))
def test_fast_and_bit_paths_accept_and_reject_alike(ftype, slot, info, data):
    frame = pl.SerialFrame(ftype, slot, info, data)
    try:
        fast = pl.check_serial_frame(frame)
    except ProtocolError as exc:
        fast = type(exc)
    body = bytes([(ftype << 4) | slot, info]) + data
    raw = pl.PREAMBLE + bytes([pl.SYNC]) + body + pl.crc16(body).to_bytes(2, "big")
    try:
        bits = pl.from_line(pl.manchester_encode(raw))
    except ProtocolError as exc:
        bits = type(exc)
    assert fast == bits
