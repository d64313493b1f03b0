"""Anything may arrive: the emulator counts and drops bad datagrams and bad line captures, and never raises."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.core.clock import SimulatedClock
from antarium.firmware_proto import config, control, panel_link, polariser, replies, video
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.panel_link import SerialFrame

DATAGRAM_REASONS = ("length", "type", "panel", "version", "field")


def valid_datagrams() -> list[bytes]:
    rng = np.random.default_rng(0)
    f = rng.integers(0, 30000, (20350, 2)).astype(np.uint16)
    rows = [r.tobytes() for r in video.encode_frame(f, seq=3)]
    return rows[:3] + [
        control.encode_latch(3), control.encode_status_request(1), control.encode_hello(2),
        polariser.encode_polarisers(rng.uniform(0, np.pi, (55, 9))),
        polariser.encode_polarisers(rng.uniform(0, np.pi, 9), panel=54),
        config.encode_dot_correction(7, rng.integers(0, 101, 740)), config.encode_brightness(40),
        replies.encode_version(1, 3),
    ]


VALID = valid_datagrams()


def mutate(rng, d: bytes) -> bytes:
    b = bytearray(d)
    op = rng.integers(7)
    if op == 0 and b:
        b = b[: rng.integers(len(b))]                           # truncate
    elif op == 1:
        b += rng.integers(0, 256, rng.integers(1, 400), dtype=np.uint8).tobytes()  # oversize
    elif op == 2 and b:
        b[0] = (b[0] & 0xC0) | rng.integers(55, 64)             # panel 55..63
    elif op == 3 and len(b) > 1:
        b[1] = rng.integers(256)                                # version / info
    elif op == 4 and b:
        b[0] = rng.integers(256)                                # any type
    elif op == 5 and len(b) > 4:
        b[4 + rng.integers(len(b) - 4)] = rng.integers(256)     # body byte
    elif len(b) > 2:
        b[2] = rng.integers(256)                                # opcode
    return bytes(b)


def check_books(emu: Emulator, n: int) -> None:
    s = emu.stats()
    assert s["datagrams_received"] == n
    assert s["internal_errors"] == 0, s["last_error"]
    assert s["datagrams_accepted"] + sum(s[f"rejected_{r}"] for r in DATAGRAM_REASONS) == n
    assert emu.led_values().shape == (20350, 2)


def test_thirty_thousand_mutated_datagrams():
    rng = np.random.default_rng(1)
    emu = Emulator(clock=SimulatedClock())
    n = 30_000
    for _ in range(n):
        d = VALID[rng.integers(len(VALID))]
        for _ in range(rng.integers(1, 4)):
            d = mutate(rng, d)
        emu.handle_datagram(d)
    check_books(emu, n)
    s = emu.stats()
    assert all(s[f"rejected_{r}"] > 0 for r in DATAGRAM_REASONS)
    assert s["datagrams_accepted"] > 0


#: one datagram: random bytes, a valid one, or a valid one with a byte changed, cut short or extended
ANY_DATAGRAM = st.one_of(
    st.binary(max_size=1600),
    st.sampled_from(VALID),
    st.builds(lambda d, i, v: d[:i % (len(d) + 1)] + bytes([v]) + d[i % (len(d) + 1) + 1:],
              st.sampled_from(VALID), st.integers(0, 2000), st.integers(0, 255)),
    st.builds(lambda d, n: d[:n], st.sampled_from(VALID), st.integers(0, 1200)),
    st.builds(lambda d, tail: d + tail, st.sampled_from(VALID), st.binary(min_size=1, max_size=64)),
)


@settings(max_examples=400, deadline=None)
@given(st.lists(ANY_DATAGRAM, min_size=40, max_size=80))
def test_random_datagram_streams(stream):
    """400 streams of 40..80 datagrams: 16,000 to 32,000 random and mutated datagrams."""
    emu = Emulator(clock=SimulatedClock())
    for d in stream:
        emu.handle_datagram(d)
    check_books(emu, len(stream))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.one_of(
    st.binary(max_size=300).map(lambda b: np.frombuffer(b, np.uint8) & 1),
    st.builds(lambda i, j: np.roll(panel_link.to_line(SerialFrame(1, 15, i % 128, b"")), j), st.integers(0, 255),
              st.integers(0, 200)),
    st.builds(lambda i, n: np.delete(panel_link.to_line(SerialFrame(2, i % 5, 0, bytes(18))), range(i, i + n)),
              st.integers(0, 400), st.integers(1, 40)),
), min_size=1, max_size=20), st.integers(0, 10))
def test_panel_links_survive_any_line_capture(captures, pentagon):
    emu = Emulator(clock=SimulatedClock(), line="bits")
    link = emu.links[pentagon]
    for symbols in captures:
        link.receive_line(symbols)
    s = emu.stats()
    assert s["internal_errors"] == 0
    assert emu.led_values().shape == (20350, 2)


def test_mutated_line_captures_are_counted_by_reason():
    rng = np.random.default_rng(2)
    emu = Emulator(clock=SimulatedClock(), line="bits")
    good = panel_link.to_line(SerialFrame(panel_link.ST_LATCH, panel_link.SLOT_ALL, 9, b""))
    n = 3000
    for _ in range(n):
        s = good.copy()
        kind = rng.integers(3)
        if kind == 0:
            s[rng.integers(s.size)] ^= 1                      # Manchester violation
        elif kind == 1:
            bit = rng.integers(64, s.size // 2)
            s[2 * bit: 2 * bit + 2] ^= 1                       # wrong bit after sync: CRC
        else:
            s = s[: 16 * rng.integers(0, 10)]                  # truncated: framing
        emu.links[rng.integers(11)].receive_line(s)
    st_ = emu.stats()
    assert st_["rejected_manchester"] + st_["rejected_crc"] + st_["rejected_framing"] == n
    assert min(st_["rejected_manchester"], st_["rejected_crc"], st_["rejected_framing"]) > 0
    assert st_["frames_received"] == 0 and st_["internal_errors"] == 0
