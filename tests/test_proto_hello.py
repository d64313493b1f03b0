"""HELLO until answered: a distributor that boots after the host is still met, and an incompatible one refused."""

import time

import numpy as np
import pytest

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
