"""`antarium emulate`: the emulator behind a UDP socket, as the real distributor board sits on the network."""

from __future__ import annotations

import signal
import socket
import threading
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


def serve(emulator: Emulator, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, seconds: float | None = None,
          ready=None, stop: threading.Event | None = None, handle_signals: bool = False) -> dict:
    """Answer datagrams on host:port until `seconds` pass, `stop` is set, or (with `handle_signals`, main thread
    only) SIGINT/SIGTERM arrives; returns the emulator's stats. `ready(address)` is called once bound.
    """
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, SOCKET_BUFFER_BYTES)
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SOCKET_BUFFER_BYTES)
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise RuntimeError(f"cannot listen on UDP {host}:{port}: {exc}") from exc
    stop = stop or threading.Event()

    def _stop(signum, frame):
        stop.set()

    signals = (signal.SIGINT, signal.SIGTERM) if handle_signals else ()
    previous = {s: signal.signal(s, _stop) for s in signals}
    sock.settimeout(0.1)
    end = None if seconds is None else time.monotonic() + seconds
    if ready is not None:
        ready(sock.getsockname())
    try:
        while not stop.is_set() and (end is None or time.monotonic() < end):
            try:
                data, peer = sock.recvfrom(MAX_DATAGRAM)
            except (TimeoutError, InterruptedError):
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
