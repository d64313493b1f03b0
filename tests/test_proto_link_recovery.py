"""What the link keeps for a distributor that reboots or is not what the dome needs (docs/protocol.md section 9):
dot correction and brightness come back with the polariser angles, a VERSION reply short of 55 panels or of a
required capability is flagged in one line, and one of another protocol version still says which version it is."""

import numpy as np
import pytest
from test_proto_hello import LatePeer, _later

from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import HELLO_RETRY_S, OUTAGE_S
from antarium.firmware_proto.replies import CAPABILITIES, OP_VERSION, VERSION_BODY, _reply

DOT = np.tile(np.arange(740) % 101, (55, 1))  # (55, 740) percent, LED k of every panel at k mod 101
QUARTER = np.full((55, 9), np.pi / 4)


def _configured(emulator) -> bool:
    """Whether the emulated panels hold the dot correction DOT and brightness 40 %."""
    return bool((emulator.dot == DOT).all() and (emulator.brightness == 40).all())


def _set_up() -> LatePeer:
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.send_config(dot_correction=DOT, brightness=40)
    assert _configured(link.emulator) and link.emulator.counters["config_updates"] == 56
    return link


def test_dot_correction_and_brightness_are_sent_again_to_a_distributor_that_rebooted_in_an_outage(monkeypatch):
    """Panels power up at 100 % (section 4); the link sent only the polariser angles again, so a rebooted dome
    ran at full brightness without its dot correction while the host had set 40 % (until 2026-11-27)."""
    link = _set_up()
    link.send_polarisers(QUARTER)
    link.up = False
    _later(monkeypatch, OUTAGE_S + 0.5)
    assert link.telemetry()["hello"] == "waiting"
    link.emulator, link.up = Emulator(), True  # rebooted: dot correction and brightness 100 %, angles 0
    monkeypatch.undo()
    _later(monkeypatch, OUTAGE_S + 0.5 + HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert status["hello"] == "answered" and _configured(link.emulator)
    assert np.allclose(link.emulator.actuators.target, np.pi / 4)
    assert status["link"]["state_resent"] == 57  # 55 dot corrections, the brightness, the polarisers
    for _ in range(3):  # known to be there again: not sent again
        link.telemetry(wait_s=0.1)
    counters = link.emulator.counters
    assert counters["config_updates"] == 56 and counters["polariser_updates"] == 1


def test_a_distributor_that_restarted_between_two_polls_gets_its_settings_again():
    """No outage long enough for a HELLO, and nothing like the ACTUATORS check for settings: its COUNTERS, which
    start again from 0, tell the host (until 2026-11-27 the dome stayed at 100 %)."""
    link = _set_up()
    link.telemetry(wait_s=0.1)
    link.emulator = Emulator()
    status = link.telemetry(wait_s=0.1)
    assert _configured(link.emulator) and link.emulator.counters["config_updates"] == 56
    assert status["hello"] == "waiting"  # its firmware may have changed: VERSION is asked for again
    _ = [link.telemetry(wait_s=0.1) for _ in range(3)]
    assert link.emulator.counters["config_updates"] == 56


class FailingPeer(LatePeer):
    """LatePeer whose transport fails (nothing handed on, False returned) while `failing` is set."""

    failing = False

    def _transmit(self, data) -> bool:
        return not self.failing and super()._transmit(data)


def test_settings_that_did_not_go_out_are_sent_with_the_next_telemetry():
    """`send_config` is called once (docs/real_rig.md); a send that failed was never tried again."""
    link = FailingPeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.failing = True
    link.send_config(dot_correction=DOT, brightness=40)
    assert link.counters["datagrams_failed"] == 56 and link.emulator.counters["config_updates"] == 0
    link.failing = False
    link.telemetry(wait_s=0.1)
    assert _configured(link.emulator) and link.emulator.counters["config_updates"] == 56


class VersionPeer(LatePeer):
    """LatePeer whose HELLO is answered by `version(tag)` (the reply's bytes) instead of the emulator."""

    def __init__(self, version):
        self.version = version
        super().__init__()

    def _transmit(self, data) -> bool:
        data = bytes(data)
        if self.up and data[2] == 0x06:
            self.inbox.append(self.version(data[3]))
            return True
        return super()._transmit(data)


def _version_peer(**fields) -> VersionPeer:
    """A peer answering with a protocol-1 VERSION, `fields` replacing what the emulator reports."""
    body = {"protocol_version": 1, "firmware_major": 1, "firmware_minor": 0, "n_panels": 55,
            "pixels_per_panel": 370, "capabilities": sum(CAPABILITIES.values()), **fields}
    return VersionPeer(lambda tag: _reply(OP_VERSION, tag, VERSION_BODY.pack(**body)))


@pytest.mark.parametrize(("fields", "line"), [
    ({"n_panels": 54}, "the distributor reports 54 panels, 55 required (check the panel cables and power)"),
    ({"pixels_per_panel": 360}, "the distributor reports 360 pixels per panel, 370 required (wrong panel firmware)"),
    ({"capabilities": 0x3F & ~0x02 & ~0x10},
     "the distributor reports capability 0x002d, without dot_correction, temperature; required: polarisers, "
     "dot_correction, brightness, fault_detection, temperature (update the distributor's firmware)"),
])
def test_a_distributor_short_of_what_the_dome_needs_is_flagged_in_one_line(monkeypatch, fields, line):
    """Until 2026-11-27 a VERSION of 54 panels or without polarisers passed unremarked; it is flagged, not refused:
    the panels that answer still show the frames."""
    link = _version_peer(**fields)
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert status["mismatch"] == line and link.mismatch == line and "incompatible" not in status
    link.send_frame(np.zeros((20350, 2), np.uint16))
    assert link.emulator.counters["frames_received"] == 1


def test_what_the_dome_needs_is_not_flagged(monkeypatch):
    link = _version_peer(capabilities=0x1F)  # IMMEDIATE is optional
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    assert "mismatch" not in link.telemetry(wait_s=0.1) and link.mismatch is None


def test_a_distributor_of_another_protocol_version_says_which_in_telemetry(monkeypatch):
    """Only the header of its VERSION is read (section 2); telemetry had no "version" at all (until 2026-11-27)."""
    link = VersionPeer(lambda tag: bytes([0xBF, 0x02, 0x81, tag, 2, 2, 0, 55, 1, 0x72, 0, 0x3F]))
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert status["version"] == {"protocol_version": 2} and "protocol version 2" in status["incompatible"]
    assert "mismatch" not in status
    assert link.hello(wait_s=0.1) == {"protocol_version": 2}
