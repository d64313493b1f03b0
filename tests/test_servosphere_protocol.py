"""Servosphere wire format v1: golden bytes, typed errors, a stream decoder that survives garbled lines."""

import random

import pytest

from antarium.locomotion.servosphere import protocol as p

SET_RATES = p.SetRates(seq=7, rate1=100, rate2=-200, rate3=300)
SET_RATES_BYTES = bytes.fromhex("a55a01010e07006400000038ffffff2c0100001dfc")
STATUS = p.Status(seq=7, t_us=123456, steps1=1, steps2=-2, steps3=3, faults=p.FAULT_WATCHDOG)
STATUS_BYTES = bytes.fromhex("a55a018113070040e2010001000000feffffff03000000081562")


def test_crc_is_ccitt_false():
    assert p.crc16(b"123456789") == 0x29B1


@pytest.mark.parametrize("msg, golden", [(SET_RATES, SET_RATES_BYTES), (STATUS, STATUS_BYTES),
                                         (p.Stop(1), bytes.fromhex("a55a0102020100") + p.CRC.pack(
                                             p.crc16(bytes.fromhex("0102020100"))))])
def test_golden_bytes_encode_and_decode(msg, golden):
    assert p.encode(msg) == golden
    assert p.decode(golden) == msg


@pytest.mark.parametrize("data, error", [
    (SET_RATES_BYTES[:-1] + b"\x00", p.ChecksumError),
    (SET_RATES_BYTES[:-3], p.LengthError),
    (b"\x00" + SET_RATES_BYTES[1:], p.ProtocolError),
])
def test_bad_messages_raise_typed_errors(data, error):
    with pytest.raises(error):
        p.decode(data)


def _reframe(body: bytes) -> bytes:
    return p.SYNC + body + p.CRC.pack(p.crc16(body))


def test_version_and_type_errors_name_what_is_allowed():
    with pytest.raises(p.VersionError, match="allowed: 1"):
        p.decode(_reframe(bytes([2]) + SET_RATES_BYTES[3:-2]))
    with pytest.raises(p.UnknownTypeError, match="allowed"):
        p.decode(_reframe(bytes([1, 0x55, 0])))
    with pytest.raises(p.LengthError, match="Stop payload must be 2"):
        p.decode(_reframe(bytes([1, p.Stop.TYPE, 1, 0])))


def test_out_of_range_field_is_refused():
    with pytest.raises(p.ProtocolError, match="out of range"):
        p.encode(p.SetRates(70000, 0, 0, 0))


def test_decoder_splits_joins_and_resynchronises():
    d = p.Decoder()
    stream = b"\x00\xa5" + SET_RATES_BYTES + STATUS_BYTES
    out = []
    for i in range(0, len(stream), 5):  # arrives in 5-byte chunks
        out += d.feed(stream[i:i + 5])
    assert out == [SET_RATES, STATUS]
    assert sum(d.errors.values()) >= 1


def test_decoder_loses_only_the_garbled_messages():
    rng = random.Random(3)
    msgs = [p.SetRates(i, i, -i, 2 * i) for i in range(200)]
    stream = bytearray()
    garbled = set()
    for m in msgs:
        b = bytearray(p.encode(m))
        if rng.random() < 0.1:
            b[rng.randrange(len(b))] ^= 1 << rng.randrange(8)
            garbled.add(m.seq)
        stream += b
    got = p.Decoder().feed(bytes(stream))
    seqs = {m.seq for m in got}
    assert {m.seq for m in msgs} - garbled <= seqs  # every intact message came through
    assert seqs <= {m.seq for m in msgs} and all(m == msgs[m.seq] for m in got)  # nothing mis-read
