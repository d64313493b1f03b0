"""What docs/protocol.md now states for an independent decoder, checked against the emulator's own bytes."""

from pathlib import Path

import numpy as np

from antarium.firmware_proto.control import encode_hello, encode_status_request
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.replies import OP_ACTUATORS, OP_COUNTERS, OP_VERSION

DOC = (Path(__file__).parents[1] / "docs" / "protocol.md").read_text()
REJECTS = ("rejected_length", "rejected_type", "rejected_panel", "rejected_version", "rejected_field")


def _replies(emulator, datagram):
    return {d[2]: d for d in emulator.handle_datagram(datagram)}


def test_every_counters_reply_counts_its_request_as_received_not_yet_accepted():
    from antarium.firmware_proto.replies import decode_reply

    assert "datagrams_received = datagrams_accepted + rejected_… + 1" in DOC
    em = Emulator()
    em.handle_datagram(b"\x00")   # one bad datagram too
    for tag in range(3):
        c = decode_reply(_replies(em, encode_status_request(tag))[OP_COUNTERS]).fields
        assert c["datagrams_received"] == c["datagrams_accepted"] + sum(c[k] for k in REJECTS) + 1
        assert c["status_requests"] == tag + 1


def test_capability_bits_count_from_the_least_significant_bit():
    assert "bit n has the value 2ⁿ" in DOC
    body = _replies(Emulator(), encode_hello(1))[OP_VERSION]
    assert int.from_bytes(body[-2:], "big") == 0x003F


def test_power_up_holding_bits_and_the_padding_bit():
    assert "Bit 495" in DOC and "every holding bit 1" in DOC
    data = _replies(Emulator(), encode_status_request(1))[OP_ACTUATORS]
    bits = np.unpackbits(np.frombuffer(data[-62:], np.uint8))
    assert bits[:495].all() and bits[495] == 0
    assert not np.frombuffer(data[4:4 + 990], ">u2").any()
