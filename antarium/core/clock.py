"""Injectable clocks: the frame loop and every protocol take time from one of these.

`MonotonicClock` is wall time for a real rig; `SimulatedClock` advances only when asked to sleep,
so tests and simulated ants run the same code faster than real time.
"""

from __future__ import annotations

import math
import time
from numbers import Real
from typing import Protocol


class Clock(Protocol):
    #: whether waiting on it takes real time (wall time), not a simulated jump
    realtime: bool

    def now(self) -> float:
        """Seconds on a monotonic time base."""

    def sleep_until(self, t: float) -> None:
        """Return at (or just after) time `t`; return at once if `t` has passed."""


class MonotonicClock:
    """`time.monotonic` with precise waits: sleep coarsely, then spin the last `spin_s` seconds."""

    realtime = True

    def __init__(self, spin_s: float = 0.0005) -> None:
        self.spin_s = spin_s

    def now(self) -> float:
        return time.monotonic()

    def sleep_until(self, t: float) -> None:
        remaining = t - time.monotonic()
        if remaining > self.spin_s:
            time.sleep(remaining - self.spin_s)
        while time.monotonic() < t:
            pass


class SimulatedClock:
    """A clock that jumps forward to whatever time it is asked to sleep until."""

    realtime = False

    def __init__(self, start: float = 0.0) -> None:
        if isinstance(start, bool) or not isinstance(start, Real) or not math.isfinite(start):
            raise ValueError(f"start must be a finite number of seconds, got {start!r}")
        self._t = float(start)

    def now(self) -> float:
        return self._t

    def sleep_until(self, t: float) -> None:
        self._t = max(self._t, float(t))

    def advance(self, dt: float) -> None:
        """Move the clock forward by `dt` seconds (finite, >= 0)."""
        if isinstance(dt, bool) or not isinstance(dt, Real) or not 0.0 <= dt < math.inf:
            raise ValueError(f"dt must be a finite number of seconds >= 0, got {dt!r}")
        self._t += float(dt)
