"""`antarium emulate` as a process of its own on loopback: the embedded default's dome."""

from __future__ import annotations

import socket

from antarium.core import realtime
from antarium.core.childproc import ChildProcess


class EmulatorProcess:
    """The distributor and its 55 panels, emulated in a child process listening on UDP `host`:`port`.

    port: 0 for a free port chosen now; realtime_priority: 1..99 to run it SCHED_FIFO at that priority (as
    hardware would answer), 0 for ordinary scheduling; not granted, it runs ordinary. It ends with this process
    (even one killed by SIGKILL: `ChildProcess(end_with_parent=True)`), never left holding its port and priority.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = 0, extra_args: list[str] | None = None,
                 realtime_priority: int = 0) -> None:
        self.host = host
        self.realtime_priority = realtime_priority
        self.port = port or free_udp_port(host)
        self.extra_args = list(extra_args or [])
        self.child: ChildProcess | None = None

    def start(self) -> None:
        """Start (or restart) the emulator process."""
        if self.child is not None:
            self.child.stop()
        self.child = ChildProcess("antarium", ["emulate", "--host", self.host, "--port", str(self.port),
                                               *self.extra_args], end_with_parent=True)
        if self.realtime_priority:
            try:
                realtime.set_realtime(self.realtime_priority, self.child.pid)
            except (AttributeError, OSError):
                pass

    def output(self, max_bytes: int = 4000) -> str:
        """The end of what the emulator printed (for error messages)."""
        return "" if self.child is None else self.child.output(max_bytes)

    @property
    def pid(self) -> int | None:
        return None if self.child is None else self.child.pid

    @property
    def exitcode(self) -> int | None:
        """How it ended (-N: killed by signal N); None while it runs or when it was never started."""
        return None if self.child is None else self.child.exitcode

    @property
    def running(self) -> bool:
        return self.child is not None and self.child.running

    def stop(self, timeout_s: float = 5.0) -> None:
        if self.child is not None:
            self.child.stop(timeout_s)
            self.child = None


def free_udp_port(host: str) -> int:
    """A UDP port nothing is bound to now on `host`."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind((host, 0))
        return s.getsockname()[1]
