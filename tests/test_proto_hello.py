"""HELLO until answered: a distributor that boots after the host is still met, and an incompatible one refused."""

import time

import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import HELLO_RETRY_S, OUTAGE_S, IncompatibleDistributor, Link
from antarium.firmware_proto.replies import OP_VERSION, VERSION_BODY, _reply
from antarium.firmware_proto.video import encode_frame


class LatePeer(Link):
    """The real emulator behind a UDP peer that is not there yet (not bound) until `up` is set."""

    def __init__(self, emulator=None):
        super().__init__()
        self.emulator, self.up, self.inbox = emulator or Emulator(), False, []
        self.hello()   # as the udp link does when it opens: lost, nobody listens yet

    def _transmit(self, data) -> bool:
        if self.up:
            self.inbox.extend(self.emulator.handle_datagram(bytes(data)))
        return True

    def _receive(self, timeout_s):
        return self.inbox.pop(0) if self.inbox else None


def _later(monkeypatch, seconds):
    now = time.monotonic()
    monkeypatch.setattr(time, "monotonic", lambda: now + seconds)


def test_a_distributor_that_boots_after_the_host_learns_of_it(monkeypatch):
    link = LatePeer()
    assert link.telemetry()["hello"] == "waiting" and "version" not in link.telemetry()
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert status["hello"] == "answered"
    assert status["version"]["protocol_version"] == 1 and status["version"]["n_panels"] == 55
    assert "polarisers" in status["version"]["capability_names"]


def test_hello_again_after_an_outage(monkeypatch):
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.up = False
    _later(monkeypatch, OUTAGE_S + 0.5)
    assert link.telemetry()["hello"] == "waiting"
    link.up = True
    monkeypatch.undo()
    _later(monkeypatch, OUTAGE_S + 0.5 + HELLO_RETRY_S)
    assert link.telemetry(wait_s=0.1)["hello"] == "answered"


class OtherVersionPeer(LatePeer):
    def _transmit(self, data) -> bool:
        if bytes(data)[2] == 0x06:   # HELLO: answered by a distributor of protocol version 2
            body = VERSION_BODY.pack(protocol_version=2, firmware_major=2, firmware_minor=0, n_panels=55,
                                     pixels_per_panel=370, capabilities=0x3F)
            self.inbox.append(_reply(OP_VERSION, bytes(data)[3], body))
            return True
        return super()._transmit(data)


def test_an_incompatible_distributor_gets_no_frames_and_a_clear_reason(monkeypatch):
    link = OtherVersionPeer()
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert "protocol version 2" in status["incompatible"]
    frame = np.zeros((20350, 2), np.uint16)
    sent = link.counters["datagrams_sent"]
    with pytest.raises(IncompatibleDistributor, match="protocol version 2; this host speaks 1"):
        link.send_frame(frame)
    with pytest.raises(IncompatibleDistributor, match="protocol version 2"):  # the GPU path's packed frames too
        link.send_packed(encode_frame(frame, seq=0))
    assert link.counters["frames_sent"] == 0 and link.counters["datagrams_sent"] == sent


def test_hello_says_no_answer_when_this_hello_has_none():
    """`hello(wait_s)` returns the VERSION that answers this HELLO, or None: not the one an earlier HELLO got
    (until 2026-11-26 a distributor that had answered once was reported answering ever after)."""
    link = LatePeer()
    link.up = True
    assert link.hello(wait_s=0.05)["n_panels"] == 55
    link.up = False  # the distributor is gone
    assert link.hello(wait_s=0.05) is None
    link.up = True
    assert link.hello(wait_s=0.05)["protocol_version"] == 1


def test_a_distributor_of_another_header_version_is_refused_not_ignored(monkeypatch):
    """A version-2 distributor says so in its VERSION reply's header VERSION byte (section 2); the host dropped
    that reply as a bad datagram, never learned the version and went on sending version-1 frames (until
    2026-11-27)."""

    class Version2Peer(LatePeer):
        def _transmit(self, data) -> bool:
            data = bytes(data)
            if self.up and data[2] == 0x06:  # HELLO -> VERSION with header VERSION 2 (its body may differ too)
                self.inbox.append(bytes([0xBF, 0x02, 0x81, data[3], 2, 2, 0, 55, 1, 0x72, 0, 0x3F]))
            elif self.up and data[2] == 0x05:  # its other replies are of version 2 as well: not read
                self.inbox.append(bytes([0xBF, 0x02, 0x82]) + bytes(1 + 84))
            return True

    link = Version2Peer()
    link.up = True
    _later(monkeypatch, HELLO_RETRY_S)
    status = link.telemetry(wait_s=0.1)
    assert status["hello"] == "answered"
    assert "protocol version 2; this host speaks 1" in status["incompatible"]
    assert status["link"]["replies_received"] == 1 and status["link"]["replies_rejected"] == 1
    with pytest.raises(IncompatibleDistributor, match="protocol version 2"):
        link.send_frame(np.zeros((20350, 2), np.uint16))
    assert link.counters["frames_sent"] == 0


class LossyPeer(LatePeer):
    """LatePeer whose next POLARISER datagram is lost on the way (sent, never arrives), when `lose_next` is set."""

    lose_next = False

    def _transmit(self, data) -> bool:
        if self.lose_next and bytes(data)[2] == 0x02:
            self.lose_next = False
            return True
        return super()._transmit(data)


QUARTER = np.full((55, 9), np.pi / 4)


def _holds(emulator, angles) -> bool:
    """Whether the distributor's actuators are commanded to `angles` (modulo pi)."""
    return bool(np.allclose(np.sin(emulator.actuators.target - angles), 0.0, atol=1e-4))


def test_polarisers_are_sent_again_to_a_distributor_that_rebooted_in_an_outage(monkeypatch):
    """Boards power up at angle 0 (section 5); the link skipped the angles it had sent before, so the dome kept 0
    while the host held pi/4 (until 2026-11-27)."""
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    assert link.send_polarisers(QUARTER) and _holds(link.emulator, QUARTER)
    link.up = False  # the distributor goes away ...
    _later(monkeypatch, OUTAGE_S + 0.5)
    assert link.telemetry()["hello"] == "waiting"
    link.emulator, link.up = Emulator(), True  # ... and comes back, rebooted
    monkeypatch.undo()
    _later(monkeypatch, OUTAGE_S + 0.5 + HELLO_RETRY_S)
    assert link.telemetry(wait_s=0.1)["hello"] == "answered"
    assert _holds(link.emulator, QUARTER) and link.emulator.counters["polariser_updates"] == 1
    assert not link.send_polarisers(QUARTER)  # known to be there again: not sent twice


def test_the_version_answering_hello_after_an_outage_brings_the_polarisers_back(monkeypatch):
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.send_polarisers(QUARTER)
    link.up = False
    _later(monkeypatch, OUTAGE_S + 0.5)
    assert link.telemetry()["hello"] == "waiting"
    link.emulator, link.up = Emulator(), True  # rebooted
    assert link.hello(wait_s=0.1)["n_panels"] == 55
    assert _holds(link.emulator, QUARTER)  # at once, before any status reply


def test_a_polariser_update_lost_in_an_outage_is_sent_again(monkeypatch):
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.up = False
    _later(monkeypatch, OUTAGE_S + 0.5)
    link.telemetry()
    assert link.send_polarisers(QUARTER)  # handed to the network; nobody there
    link.up = True
    monkeypatch.undo()
    _later(monkeypatch, OUTAGE_S + 0.5 + HELLO_RETRY_S)
    link.telemetry(wait_s=0.1)
    assert _holds(link.emulator, QUARTER) and link.emulator.counters["polariser_updates"] == 1


def test_a_distributor_that_restarted_between_two_polls_gets_the_polarisers_again():
    """No outage long enough for a HELLO: its ACTUATORS, at rest at angle 0, tell the host."""
    link = LatePeer()
    link.up = True
    link.telemetry(wait_s=0.1)
    link.send_polarisers(QUARTER)
    link.telemetry(wait_s=0.1)
    link.emulator = Emulator()
    link.telemetry(wait_s=0.1)
    assert _holds(link.emulator, QUARTER) and link.emulator.counters["polariser_updates"] == 1


def test_a_lost_polariser_update_is_sent_again_when_the_actuators_show_it_missing():
    clock = SimulatedClock()
    link = LossyPeer(Emulator(clock=clock))
    link.up = True
    link.telemetry(wait_s=0.1)
    link.lose_next = True
    assert link.send_polarisers(QUARTER)  # lost on the way: the actuators stay at rest at angle 0
    link.telemetry(wait_s=0.1)            # ACTUATORS: at rest, at 0 -> sent again
    assert _holds(link.emulator, QUARTER) and link.emulator.counters["polariser_updates"] == 1
    for _ in range(3):                    # turning, then at rest at pi/4: nothing more to send
        clock.advance(0.5)
        link.telemetry(wait_s=0.1)
    assert np.array(link.telemetry(wait_s=0.1)["holding"]).all()
    assert set(np.ravel(link.telemetry(wait_s=0.1)["polariser_codes"])) == {16384}
    assert link.emulator.counters["polariser_updates"] == 1
