"""The "udp" link: datagrams to a distributor board (or `antarium emulate`) at host:port.

The socket is connected, so the kernel reports an ICMP port-unreachable from a vanished peer as
ConnectionRefusedError on a later send or receive; those, and a full send buffer, are counted in
`telemetry()["link"]` and never raised, so a frame loop survives the distributor being restarted.
"""

from __future__ import annotations

import select
import socket

import numpy as np

from . import DEFAULT_HOST, DEFAULT_PORT
from .control import encode_latch
from .link import Link

__all__ = ["DEFAULT_HOST", "DEFAULT_PORT", "UdpLink"]
SOCKET_BUFFER_BYTES = 4 * 1024 * 1024
MAX_DATAGRAM = 65535


class UdpLink(Link):
    """A link over UDP to `host`:`port`; sends HELLO on open (the VERSION answer shows up in `telemetry`)."""

    status_interval_s = 0.05

    def __init__(self, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT) -> None:
        super().__init__()
        if not isinstance(port, int) or not 0 < port < 65536:
            raise ValueError(f"UDP port must be an integer 1..65535, got {port!r}")
        self.address = (host, port)
        self.counters.update(peer_refused=0, send_buffer_full=0, socket_errors=0)
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            for opt in (socket.SO_SNDBUF, socket.SO_RCVBUF):
                self.sock.setsockopt(socket.SOL_SOCKET, opt, SOCKET_BUFFER_BYTES)
            self.sock.setblocking(False)
            self.sock.connect(self.address)
        except OSError as exc:
            self.sock.close()
            raise ValueError(f"cannot open UDP link to {host}:{port}: {exc}") from exc
        self._batch = self._latch = None
        from . import batch_send

        if batch_send.available():
            self._latch = np.zeros(len(encode_latch(0)), np.uint8)
            self._batch = batch_send.MessageBatch([*self._frame_buf, self._latch])
        self.hello()

    def _send_frame_datagrams(self, latch: bytes) -> None:
        """The frame and its LATCH in one sendmmsg call where there is one; what it could not send (a full send
        buffer, a refusing peer) goes one datagram at a time, with the usual counting."""
        if self._batch is None:
            return super()._send_frame_datagrams(latch)
        if self.closed:
            raise RuntimeError("the dome link is closed")
        self._latch[:] = np.frombuffer(latch, np.uint8)
        sent, _ = self._batch.send(self.sock.fileno())
        self.counters["datagrams_sent"] += sent
        if sent < len(self._batch):
            for row in [*self._frame_buf, self._latch][sent:]:
                self.send(row.data)

    def _transmit(self, data) -> bool:
        # A ConnectionRefusedError reports an earlier datagram's ICMP port unreachable and consumes it; this
        # datagram was not sent, so it gets one more try (it goes out if the peer is back, e.g. restarted).
        for _attempt in range(2):
            try:
                self.sock.send(data)
                return True
            except ConnectionRefusedError:
                self.counters["peer_refused"] += 1
            except BlockingIOError:
                self.counters["send_buffer_full"] += 1
                return False
            except OSError:
                self.counters["socket_errors"] += 1
                return False
        return False

    def _receive(self, timeout_s: float) -> bytes | None:
        while True:
            try:
                return self.sock.recv(MAX_DATAGRAM)
            except BlockingIOError:
                if timeout_s <= 0 or not select.select([self.sock], [], [], timeout_s)[0]:
                    return None
                timeout_s = 0.0  # readable now; one more try
            except ConnectionRefusedError:
                self.counters["peer_refused"] += 1
            except OSError:
                self.counters["socket_errors"] += 1
                return None

    def close(self) -> None:
        if not self.closed:
            self.sock.close()
        super().close()
