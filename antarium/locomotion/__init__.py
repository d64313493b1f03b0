"""Locomotion sources: one interface, a registry of back-ends imported lazily (python-can style).

Every source yields `BallSample`s: timestamped ball-rotation increments with sequence numbers.
Ball axes are the dome frame's (+x forward for a fixed-tether ant, +y left, +z up); see `antarium.core.ball`
for the motion of the ant standing on the top pole.

    with open_source("scripted", speed=0.02, turn_rate=0.1, clock=clock) as src:
        samples = src.read()
"""

from __future__ import annotations

import inspect
import math
import threading
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from importlib import import_module
from typing import Any

from antarium.core.numbers import as_real


@dataclass(frozen=True, slots=True)
class BallSample:
    """One locomotion sample.

    t:        host time (s) on the loop's clock when the sample arrived
    seq:      the source's sequence number (int); a gap means samples were lost
    rotation: ball rotation increment (rad) about the dome-frame x, y, z axes since the previous sample
    t_device: device timestamp (s) if the source has one, else None
    quality:  0..1 (1 = good); e.g. derived from the slip residual of the sensor fit
    """

    t: float
    seq: int
    rotation: tuple[float, float, float]
    t_device: float | None = None
    quality: float = 1.0


class LocomotionSource(ABC):
    """A source of ball rotations. `read()` never blocks; it returns the samples since the last call.

    Building a source checks its options and opens nothing (no device, thread, socket or process: `start` does),
    so `check_config` builds one to check a config's options.
    """

    def start(self) -> None:  # noqa: B027 - sources without set-up need not override
        """Open devices, threads or subscriptions."""

    def stop(self) -> None:  # noqa: B027
        """Release everything `start` took. Safe to call twice."""

    @abstractmethod
    def read(self) -> list[BallSample]:
        """All samples that arrived since the previous call, oldest first (may be empty)."""

    def status(self) -> dict[str, Any]:
        """Counters and state for the server's status message (JSON-serialisable)."""
        return {"connected": True}

    def lost_hint(self) -> str:
        """What the operator should check when this source delivers nothing: one clause ("" when its status's
        error says it all)."""
        return ""

    def __enter__(self) -> LocomotionSource:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()


class BufferedSource(LocomotionSource):
    """A source whose samples arrive on another thread (a device reader, a socket, a bus callback).

    That thread calls `_push(sample)`; `read()` hands over everything pushed since the previous call. At most
    `max_pending` samples wait: beyond that the oldest is dropped and `_push` returns True so the caller can
    count it. `_lock` may also guard the subclass's own counters.
    """

    def __init__(self, max_pending: int = 100_000, option: str = "max_pending") -> None:
        if isinstance(max_pending, bool) or not isinstance(max_pending, int) or max_pending < 1:
            raise ValueError(f"{option} must be an integer >= 1 (samples that may wait for read()), got "
                             f"{max_pending!r}")
        self._lock = threading.Lock()
        self._pending: deque[BallSample] = deque(maxlen=max_pending)

    def _push(self, sample: BallSample) -> bool:
        """Queue one sample (any thread); True if the queue was full and the oldest sample was dropped."""
        with self._lock:
            full = len(self._pending) == self._pending.maxlen
            self._pending.append(sample)
        return full

    def read(self) -> list[BallSample]:
        with self._lock:
            out = list(self._pending)
            self._pending.clear()
        return out


class ReaderSource(BufferedSource):
    """A buffered source fed by a reader thread of its own (a USB device, a socket).

    Subclasses implement `_run()`, the thread's body, which returns once `_stop` is set; `_open()` runs in
    `start`'s caller before the thread (it may raise: nothing is started then), `_close()` in `stop`'s after the
    thread ended. `thread_name` names the thread.
    """

    thread_name = "locomotion-reader"

    def __init__(self, max_pending: int = 100_000, option: str = "max_pending") -> None:
        super().__init__(max_pending, option)
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        if self._thread is not None:
            return
        self._open()
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name=self.thread_name, daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            self._thread = None
        self._close()

    def _open(self) -> None:  # noqa: B027 - a source without set-up need not override
        """Take what the thread reads from; runs before the thread starts."""

    def _close(self) -> None:  # noqa: B027
        """Release what `_open` took; runs after the thread ended. Safe to call twice."""

    @abstractmethod
    def _run(self) -> None:
        """The reader thread: push samples until `_stop` is set."""


#: back-end name -> "module:Class", imported only when opened.
BACKENDS: dict[str, str] = {
    "scripted": "antarium.locomotion.scripted:ScriptedSource",
    "replay": "antarium.locomotion.replay:ReplaySource",
    "bus": "antarium.locomotion.bus:BusSource",
    "usb": "antarium.locomotion.trackball.driver:UsbTrackball",
    "fictrac": "antarium.locomotion.fictrac.source:FicTracSource",
    "fictrac-replay": "antarium.locomotion.fictrac.source:FicTracReplay",
    "ant": "antarium.ant.locomotion:AntLocomotion",
    "servosphere": "antarium.locomotion.servosphere.process:servosphere_source",
}


def open_source(name: str, **kwargs: Any) -> LocomotionSource:
    """Instantiate the locomotion back-end `name` with `kwargs` (not started).

    ValueError for an unknown back-end or a value it refuses; TypeError for an option it does not take, listing those
    it takes.
    """
    try:
        target = BACKENDS[name]
    except KeyError:
        raise ValueError(
            f"unknown locomotion source {name!r}; allowed: {', '.join(sorted(BACKENDS)) or 'none'}"
        ) from None
    module_name, cls_name = target.split(":")
    factory = getattr(import_module(module_name), cls_name)
    check_keywords(f"source {name!r}", factory, kwargs)
    return factory(**kwargs)


def check_keywords(what: str, factory: Any, kwargs: dict[str, Any]) -> None:
    """TypeError naming the first key of `kwargs` that `factory` takes no parameter for, and those it takes
    (nothing is checked for a factory that takes any keyword: it checks them itself)."""
    params = inspect.signature(factory).parameters
    if any(p.kind is p.VAR_KEYWORD for p in params.values()):
        return
    unknown = sorted(set(kwargs) - set(params))
    if unknown:
        raise TypeError(f"{what} has no option {unknown[0]!r}; allowed: {', '.join(sorted(params))}")


def positive(value: Any, what: str, unit: str) -> float:
    """`value` as a float if it is a finite number > 0, else ValueError naming `what` and its `unit`."""
    number = as_real(value)
    if not (math.isfinite(number) and number > 0):
        raise ValueError(f"{what} must be a finite number > 0 ({unit}), got {value!r}")
    return number
