"""`antarium emulate`: the emulator behind a UDP socket, as the real distributor board sits on the network."""

from __future__ import annotations

import signal
import socket
import time

from .emulator import Emulator
from .udp import DEFAULT_HOST, DEFAULT_PORT, MAX_DATAGRAM, SOCKET_BUFFER_BYTES


def format_stats(stats: dict) -> str:
    """Counters as aligned `name value` lines (zero rejection counters left out)."""
    lines = [f"  {k:<22} {v}" for k, v in stats.items()
             if k != "last_error" and (v or not k.startswith("rejected_"))]
    if stats.get("last_error"):
        lines.append(f"  last rejection: {stats['last_error']}")
    return "\n".join(lines)


def serve(emulator: Emulator, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
          seconds: float | None = None, ready=None) -> dict:
    """Answer datagrams on host:port until `seconds` pass (None: until SIGINT/SIGTERM); returns the stats.

    `ready(address)` is called once the socket is bound.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER_BYTES)
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise RuntimeError(f"cannot listen on UDP {host}:{port}: {exc}") from exc
    stop = False

    def _stop(signum, frame):
        nonlocal stop
        stop = True

    previous = {s: signal.signal(s, _stop) for s in (signal.SIGINT, signal.SIGTERM)}
    sock.settimeout(0.1)
    end = None if seconds is None else time.monotonic() + seconds
    if ready is not None:
        ready(sock.getsockname())
    try:
        while not stop and (end is None or time.monotonic() < end):
            try:
                data, peer = sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                continue
            except InterruptedError:
                continue
            except OSError:
                continue  # e.g. ICMP from a vanished client; the board keeps going
            for reply in emulator.handle_datagram(data):
                try:
                    sock.sendto(reply, peer)
                except OSError:
                    emulator.counters["reply_send_errors"] += 1
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
        sock.close()
    return emulator.stats()
