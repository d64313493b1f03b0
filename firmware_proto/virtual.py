"""The "virtual" link: the emulator in-process, reached through exactly the datagrams a real board gets."""

from __future__ import annotations

from collections import deque

from antarium.core.clock import Clock

from .emulator import Emulator
from .link import Link


class VirtualLink(Link):
    """A link to an in-process `Emulator` (`emulator`, or a new one built with `clock` and `line`); like the
    udp link it says HELLO on open."""

    def __init__(self, emulator: Emulator | None = None, clock: Clock | None = None, line: str = "fast",
                 **emulator_kwargs) -> None:
        super().__init__()
        self.emulator = emulator if emulator is not None else Emulator(clock=clock, line=line, **emulator_kwargs)
        self._inbox: deque[bytes] = deque()
        self.hello()

    def _transmit(self, data) -> bool:
        self._inbox.extend(self.emulator.handle_datagram(bytes(data)))
        return True

    def _receive(self, timeout_s: float) -> bytes | None:
        return self._inbox.popleft() if self._inbox else None
