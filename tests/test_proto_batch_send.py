"""A frame's datagrams in one sendmmsg call (UDP link), and frames packed elsewhere (`Link.send_packed`)."""

from __future__ import annotations

import socket

import numpy as np
import pytest

from antarium.firmware_proto import batch_send
from antarium.firmware_proto.control import encode_latch
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.video import decode_frame, encode_frame


@pytest.fixture
def peer():
    """A plain UDP socket standing for the distributor (the lowest seam: the UDP peer)."""
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    yield s
    s.close()


def frame(k: int) -> np.ndarray:
    rng = np.random.default_rng(k)
    f = rng.integers(0, 30000, (20350, 2)).astype(np.uint16)
    return f


def received(peer, n: int) -> list[bytes]:
    return [peer.recv(65535) for _ in range(n)]


@pytest.mark.parametrize("batched", [True, False])
def test_a_frame_goes_out_whole_and_in_order(peer, batched):
    with open_link("udp", host="127.0.0.1", port=peer.getsockname()[1]) as link:
        if batched:
            assert link._batch is not None or not batch_send.available()
        else:
            link._batch = None  # the one-datagram-at-a-time path, as where sendmmsg is missing
        received(peer, 1)  # HELLO
        f = frame(1)
        seq = link.send_frame(f)
        got = received(peer, 56)
        assert got[:55] == [row.tobytes() for row in encode_frame(f, seq)]
        assert got[55] == encode_latch(seq)
        assert link.counters["datagrams_sent"] == 1 + 56 and link.counters["datagrams_failed"] == 0


@pytest.mark.skipif(not batch_send.available(), reason="sendmmsg is Linux-only")
def test_message_batch_sends_a_leading_run_and_rewritten_buffers(peer):
    bufs = [np.full(10, k, np.uint8) for k in range(4)]
    batch = batch_send.MessageBatch(bufs)
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.connect(peer.getsockname())
        assert batch.send(s.fileno(), 2) == (2, 0)
        bufs[0][:] = 9
        assert batch.send(s.fileno()) == (4, 0)
    assert received(peer, 6) == [bytes([0] * 10), bytes([1] * 10), bytes([9] * 10), bytes([1] * 10),
                                 bytes([2] * 10), bytes([3] * 10)]
    with pytest.raises(ValueError, match="C-contiguous uint8"):
        batch_send.MessageBatch([np.zeros(4, np.uint16)])


def test_send_packed_sets_the_sequence_and_the_dome_shows_the_frame():
    f = frame(2)
    packed = encode_frame(f, seq=0)
    packed[:, 1] = 0x55  # whatever INFO the packer left
    with open_link("virtual") as link:
        link.send_frame(frame(3))
        seq = link.send_packed(packed)
        assert seq == 1
        assert np.array_equal(link.emulator.led_values(), decode_frame(encode_frame(f, seq)))
        sent = link.counters["datagrams_sent"]
        with pytest.raises(ValueError, match=r"\(55, 1112\) uint8"):
            link.send_packed(packed[:54])
        bad = packed.copy()
        bad[3, 0] = 7
        with pytest.raises(ValueError, match="VIDEO TD of panel k"):
            link.send_packed(bad)
        assert link.counters["datagrams_sent"] == sent  # nothing sent
