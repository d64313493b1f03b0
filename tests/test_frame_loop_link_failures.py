"""The frame loop's view of the dome link: one datagram that the kernel could not take (a full send buffer) is
counted, not reported as an outage; failures that go on for LINK_FAILING_S are one."""

import socket
import threading

import pytest

from antarium.core.clock import MonotonicClock
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import open_link
from antarium.server.frame_loop import LINK_FAILING_S, FrameLoop


class FullBuffer:
    """The link's UDP socket, whose sends find the kernel's send buffer full (EAGAIN) while `full` is set;
    `once`: only the next send."""

    def __init__(self, sock):
        self.sock, self.full, self.once = sock, False, False

    def send(self, data):
        if self.full:
            self.full = not self.once
            raise BlockingIOError(11, "Resource temporarily unavailable")
        return self.sock.send(data)

    def __getattr__(self, name):
        return getattr(self.sock, name)


@pytest.fixture
def board():
    """The real emulator behind a loopback UDP port (yields the port)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(0.05)
    emulator, done = Emulator(), threading.Event()

    def serve():
        while not done.is_set():
            try:
                data, peer = sock.recvfrom(65535)
            except TimeoutError:
                continue
            for reply in emulator.handle_datagram(data):
                sock.sendto(reply, peer)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    yield sock.getsockname()[1]
    done.set()
    thread.join()
    sock.close()


def _loop(port):
    link = open_link("udp", host="127.0.0.1", port=port)
    link.sock = FullBuffer(link.sock)
    events = []
    loop = FrameLoop(clock=MonotonicClock(), source=None, link=link, rate_hz=100.0,
                     on_event=lambda t, kind, info: events.append(kind))
    loop.run(frames=50)  # the distributor answers: link up
    assert loop.link_ok
    return link, loop, events


def test_one_full_send_buffer_is_counted_not_an_outage(board):
    link, loop, events = _loop(board)
    link.sock.full = link.sock.once = True
    loop.run(frames=100)
    link.close()
    assert link.counters["send_buffer_full"] == 1 and link.counters["datagrams_failed"] == 1
    assert loop.link_outages == 0 and "link_outage" not in events, events
    assert loop.transient_link_failures == 1


def test_failures_that_go_on_are_an_outage(board):
    link, loop, events = _loop(board)
    link.sock.full = True  # every send fails from now on
    loop.run(frames=int(100 * (LINK_FAILING_S + 0.5)))
    link.sock.full = False
    loop.run(frames=100)
    link.close()
    assert loop.link_outages == 1 and events.count("link_outage") == 1 and "link_back" in events, events
    assert loop.link_ok
