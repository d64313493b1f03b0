"""Review of the wire protocol against docs/protocol.md (2026-11-27): an encoder written from the page alone for the
replies, control and panel-link messages; the order in which a doubly faulty datagram is counted; and the defects
found (a VERSION of 64 or more panels dropped instead of flagged, percents above 100 taken by a panel from its link,
header fields truncated from floats, CLI errors that did not name their option)."""

import math
import socket
import struct

import numpy as np
import pytest
from test_proto_panel_link import crc16_bitwise  # the reference CRC, bit by bit as section 7 states it

from antarium.core.clock import SimulatedClock
from antarium.firmware_proto import config, control, panel_link, polariser, replies
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.video import encode_frame


def _header(cls: int, address: int, opcode: int, info: int) -> bytes:
    return bytes([(cls << 6) | address, 1, opcode, info])


def _line_frame(ftype: int, slot: int, info: int, data: bytes) -> bytes:
    body = bytes([(ftype << 4) | slot, info]) + data
    return b"\x55" * 7 + b"\xd5" + body + crc16_bitwise(body).to_bytes(2, "big")


def test_replies_control_and_panel_link_match_an_encoder_written_from_the_doc():
    rng = np.random.default_rng(3)
    names = ("datagrams_received datagrams_accepted frames_received frames_latched frames_dropped panel_misses "
             "superseded immediate polariser_updates config_updates status_requests rejected_length rejected_type "
             "rejected_panel rejected_version rejected_field rejected_stale rejected_framing rejected_manchester "
             "rejected_crc").split()
    counts = {n: int(v) for n, v in zip(names, rng.integers(0, 2**32, len(names)), strict=True)}
    assert replies.encode_counters(3, counts) == (
        _header(2, 63, 0x82, 3) + b"".join(struct.pack(">I", counts[n]) for n in names))
    t, i = rng.uniform(-20, 90, 55), rng.uniform(0, 8, 55)
    assert replies.encode_temperatures(1, t, i) == (
        _header(2, 63, 0x83, 1) + b"".join(struct.pack(">h", round(x * 100)) for x in t)
        + b"".join(struct.pack(">H", round(x * 1000)) for x in i))
    faults = [(3, 120, "open"), (54, 739, "short")]
    assert replies.encode_faults(2, faults) == (
        _header(2, 63, 0x84, 2) + struct.pack(">H", 2)
        + b"".join(struct.pack(">BHB", p, k, {"open": 1, "short": 2}[kind]) for p, k, kind in faults))
    codes, hold = rng.integers(0, 65536, (55, 9)), rng.random((55, 9)) < 0.5
    bits = bytearray(62)
    for k in np.flatnonzero(hold.ravel()):
        bits[k // 8] |= 0x80 >> (k % 8)
    assert replies.encode_actuators(9, codes, hold) == (
        _header(2, 63, 0x85, 9) + b"".join(struct.pack(">H", c) for c in codes.ravel()) + bytes(bits))
    dome = rng.random((55, 9)) * 3.14
    assert polariser.encode_polarisers(dome) == _header(1, 63, 2, 0) + b"".join(
        struct.pack(">H", round(a * 65536 / math.pi) % 65536) for a in dome.ravel())
    dot = rng.integers(0, 101, 740).astype(np.uint8)
    assert config.encode_dot_correction(7, dot) == _header(1, 7, 3, 0) + bytes(dot)
    for ftype, slot, data in [(2, 3, bytes(range(18))), (3, 1, bytes(dot)), (4, 15, b"\x32"), (5, 4, b"")]:
        assert panel_link.to_bytes(panel_link.SerialFrame(ftype, slot, 0, data)) == _line_frame(ftype, slot, 0, data)


@pytest.mark.parametrize(("datagram", "reason"), [
    (b"\xc0\x02" + bytes(3), "type"),                       # class 3 and a wrong length: type
    (b"\x37\x00" + bytes(1000), "length"),                  # VIDEO to panel 55, short: length first
    (b"\x7f\x02\x09\x00\x00", "version"),                   # wrong version and opcode and length: version
    (b"\x7f\x01\x09\x00", "type"),                          # unknown opcode
    (b"\x42\x01\x01\x80\x00", "length"),                    # LATCH to a panel, seq 128, 5 bytes: length
    (b"\x42\x01\x01\x80", "panel"),                         # LATCH to a panel, seq 128: panel
    (b"\x77\x01\x02\x05" + bytes(17), "panel"),             # POLARISER to 55, short, INFO 5: panel
    (b"\x42\x01\x02\x05" + bytes(17), "length"),            # POLARISER to a panel, short, INFO 5: length
    (b"\x7f\x01\x04\x01\x65\x00", "length"),                # BRIGHTNESS 6 bytes, INFO 1, 101 %: length
    (b"\x42\x01\x04\x01\x65", "panel"),                     # BRIGHTNESS to a panel, INFO 1, 101 %: panel
    (b"\x7f\x01\x03\x01" + bytes(740), "panel"),            # DOT_CORRECTION to 63, INFO 1: panel
])
def test_a_doubly_faulty_datagram_is_counted_under_the_first_documented_check(datagram, reason):
    emu = Emulator(clock=SimulatedClock())
    assert emu.handle_datagram(datagram) == []
    rejected = {k[len("rejected_"):] for k, v in emu.counters.items() if k.startswith("rejected_") and v}
    assert rejected == {reason} and emu.counters["datagrams_accepted"] == 0


def test_the_class_error_names_both_classes_the_board_takes():
    emu = Emulator(clock=SimulatedClock())
    emu.handle_datagram(b"\xbf\x01\x81\x00")
    assert emu.last_error == "message class 2 not accepted by the distributor: allowed 0 (video), 1 (control)"


def test_a_version_of_64_or_more_panels_is_flagged_not_dropped():
    """Until this review VERSION's uint8 panel count was read as 0..63: a reply of 64 or more panels was dropped as
    malformed, so the link said "waiting" for ever instead of flagging it (section 5)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as peer:
        peer.bind(("127.0.0.1", 0))
        peer.settimeout(2.0)
        for n in (64, 200):
            with open_link("udp", port=peer.getsockname()[1]) as link:
                data, address = peer.recvfrom(2000)
                while data[2] != 0x06:  # the previous link's last datagrams, then this one's HELLO
                    data, address = peer.recvfrom(2000)
                peer.sendto(_header(2, 63, 0x81, data[3]) + struct.pack(">BBBBHH", 1, 1, 0, n, 370, 0x3F), address)
                status = link.telemetry(wait_s=0.5)
                assert status["hello"] == "answered" and status["version"]["n_panels"] == n
                assert status["mismatch"] == (f"the distributor reports {n} panels, 55 required (check the panel "
                                              "cables and power)")
                assert status["link"]["replies_rejected"] == 0


@pytest.mark.parametrize(("ftype", "slot", "data"), [
    (panel_link.ST_DOT_CORRECTION, 0, bytes([100] * 739 + [255])),
    (panel_link.ST_BRIGHTNESS, panel_link.SLOT_ALL, bytes([101])),
])
def test_a_panel_refuses_a_percent_above_100_from_its_link(ftype, slot, data):
    """A CRC-valid frame with a percent above 100 (the distributor never sends one; a corrupted frame can) was taken
    by the panel and wrapped its drive: 60000 at 255 % showed 21928. It is refused, "field", on both paths."""
    emu = Emulator(clock=SimulatedClock(), line="bits")
    frame = np.zeros((20350, 2), np.uint16)
    frame[:5 * 370, 0] = 60000
    for d in encode_frame(frame, 0):
        emu.handle_datagram(d.tobytes())
    emu.handle_datagram(control.encode_latch(0))
    before = emu.led_values().copy()
    emu.links[0].receive_line(panel_link.manchester_encode(_line_frame(ftype, slot, 0, data)))
    assert emu.counters["rejected_field"] == 1 and emu.counters["internal_errors"] == 0
    assert np.array_equal(emu.led_values(), before)
    assert (emu.dot == 100).all() and (emu.brightness == 100).all()
    with pytest.raises(ValueError, match="allowed 0..100"):
        panel_link.check_serial_frame(panel_link.SerialFrame(ftype, slot, 0, data))


@pytest.mark.parametrize(("call", "match"), [
    (lambda: control.encode_latch(5.7), "must be an integer"),
    (lambda: control.encode_status_request(True), "must be an integer"),
    (lambda: control.encode_hello(2.999), "must be an integer"),
    (lambda: polariser.encode_polarisers(np.zeros(9), panel=2.0), "allowed 0..54"),  # was a TypeError
    (lambda: config.encode_dot_correction(2.0, np.zeros(740, np.uint8)), "allowed 0..54"),
])
def test_header_fields_refuse_floats_and_bools_instead_of_truncating_them(call, match):
    with pytest.raises(ValueError, match=match):
        call()
    assert control.encode_latch(np.int64(5)) == b"\x7f\x01\x01\x05"
    assert polariser.encode_polarisers(np.zeros(9), panel=np.int64(2))[:4] == b"\x42\x01\x02\x00"


@pytest.mark.parametrize("spec", ["99:2:open", "1:2:melted", "1:2"])
def test_emulate_names_the_fault_option_that_is_wrong(capsys, spec):
    from antarium.cli import main

    assert main(["emulate", "--port", "0", "--seconds", "0.1", "--fault", spec]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"--fault {spec!r}: " in err[0]


def test_bench_protocol_refuses_a_single_frame_before_any_work(capsys):
    """One frame has no loopback rate: it printed "1 frames at nan/s" and wrote NaN (not JSON) to --json."""
    from antarium.cli import main

    assert main(["bench", "protocol", "--frames", "1", "--seconds", "0.1"]) == 2
    assert "--frames must be at least 2" in capsys.readouterr().err


def test_driver_values_round_halves_up_as_documented():
    emu = Emulator(clock=SimulatedClock())
    frame = np.zeros((20350, 2), np.uint16)
    frame[0], frame[1] = (1, 0), (3, 0)  # green LEDs 0 and 2 of panel 0
    for d in encode_frame(frame, 0):
        emu.handle_datagram(d.tobytes())
    emu.handle_datagram(control.encode_latch(0))
    dot = np.full(740, 100, np.uint8)
    dot[[0, 2]] = 50
    emu.handle_datagram(config.encode_dot_correction(0, dot))
    assert emu.led_values()[:2, 0].tolist() == [1, 2]  # 0.5 -> 1, 1.5 -> 2


def test_emulate_on_a_busy_port_says_what_to_do(capsys):
    from antarium.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        assert main(["emulate", "--port", str(s.getsockname()[1]), "--seconds", "0.1"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Address already in use" in err[0] and "--port, 0 for a free one" in err[0]


@pytest.mark.parametrize("then_dark", [False, True])
def test_a_change_held_back_by_the_power_refresh_limit_still_heats_the_panel(then_dark):
    """A frame latched within 50 ms of the previous power refresh, then a static scene: the panels' heat input kept
    the old frame's power until the next status poll (or the next change), so 30 min of a white dome read 30.8 degC
    instead of 68 degC (section 8)."""
    from antarium.firmware_proto.replies import decode_reply

    clock = SimulatedClock(0.0)
    emu = Emulator(clock=clock)
    white = np.zeros((20350, 2), np.uint16)
    white[:, 0] = 65535
    for seq, frame in enumerate((np.zeros_like(white), white)):
        for d in encode_frame(frame, seq):
            emu.handle_datagram(d.tobytes())
        emu.handle_datagram(control.encode_latch(seq))
        clock.advance(0.01)
    clock.advance(1800.0)  # six time constants
    if then_dark:  # the next change comes before anybody asks
        for d in encode_frame(np.zeros_like(white), 2):
            emu.handle_datagram(d.tobytes())
        emu.handle_datagram(control.encode_latch(2))
    temperatures = decode_reply(emu.handle_datagram(control.encode_status_request(1))[1]).fields["temperature_c"]
    assert temperatures == pytest.approx([68.0] * 55, abs=0.3)
