"""The decimated LED stream `antarium/<rig>/leds`: what the dome shows, for monitors (see docs/bus.md).

Struct (little-endian): `u8 version = 1`, `u8 reserved`, `u16 channels` (2), `u32 frame`, `u32 pixels` (20350),
`f64 t` (s, server clock: the frame's start), `f64 t_wall` (s since the Unix epoch when the frame was handed over,
for latency measured on another process of the same computer), then `pixels x channels` u16 (the LED frame as sent:
green, blue; UV pixels carry their UV value in the first channel).

The frame loop only offers a frame (`LedPublisher.offer`: a modulo test and, every `every` frames, one 81 kB copy
when the publishing thread is idle); encoding and the zenoh put run in a thread of their own. A frame offered while
the thread is still busy with the previous one is skipped: the loop never waits for the monitor.
"""

from __future__ import annotations

import struct
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from antarium import bus
from antarium.geometry.constants import N_PIXELS

LED_VERSION = 1
LED_HEADER = struct.Struct("<BBHIIdd")  # 28 bytes
#: values per pixel: green, blue (a UV pixel: plain UV, polarised UV)
LED_CHANNELS = 2


def led_key(rig: str) -> str:
    """The decimated LED stream (`LED_HEADER` + the frame's u16 values)."""
    return bus.rig_key(rig, "leds")


def encode_leds(frame: int, t: float, t_wall: float, values: np.ndarray) -> bytes:
    """values: (pixels, channels) uint16 -> payload bytes."""
    values = np.ascontiguousarray(values, dtype="<u2")
    pixels, channels = values.shape
    return LED_HEADER.pack(LED_VERSION, 0, channels, frame & 0xFFFFFFFF, pixels, t, t_wall) + values.tobytes()


def decode_leds(payload: bytes, pixels: int | None = N_PIXELS) -> dict[str, Any]:
    """A payload as {"frame", "t", "t_wall", "values": (pixels, channels) uint16}; bus.StreamError if malformed,
    of another version, or not `pixels` (the dome's 20,350; None: any number) x `LED_CHANNELS` values."""
    if len(payload) < LED_HEADER.size:
        raise bus.StreamError(f"leds payload must be at least {LED_HEADER.size} bytes, got {len(payload)}")
    version, _, channels, frame, n, t, t_wall = LED_HEADER.unpack_from(payload)
    if version != LED_VERSION:
        raise bus.StreamError(f"leds payload version {version} not supported (allowed: {LED_VERSION})")
    if channels != LED_CHANNELS:
        raise bus.StreamError(f"leds payload of {channels} channels; allowed: {LED_CHANNELS}")
    if pixels is not None and n != pixels:
        raise bus.StreamError(f"leds payload of {n} pixels; the dome has {pixels}")
    pixels = n
    if len(payload) != LED_HEADER.size + 2 * pixels * channels:
        raise bus.StreamError(f"leds payload of {pixels} x {channels} values must be "
                              f"{LED_HEADER.size + 2 * pixels * channels} bytes, got {len(payload)}")
    values = np.frombuffer(payload, dtype="<u2", offset=LED_HEADER.size).reshape(pixels, channels)
    return {"frame": frame, "t": t, "t_wall": t_wall, "values": values}


class LedPublisher:
    """Publishes every `every`-th offered frame on `led_key(rig)` from a thread of its own. A put that fails is
    counted (`failed`, `last_error`) and reported through `report` (one line: the first failure, then every
    `REPORT_EVERY`-th); the stream goes on with the next frame."""

    #: after the first failed put, one line per this many
    REPORT_EVERY = 1000

    def __init__(self, session, rig: str, every: int, report: Callable[[str], None] | None = None) -> None:
        self.every = every
        self.failed = 0
        self.last_error: str | None = None
        self._report = report or (lambda line: print(line, file=sys.stderr, flush=True))
        self._pub = session.declare_publisher(led_key(rig))
        self._buf: np.ndarray | None = None
        self._meta = (0, 0.0, 0.0)
        self._busy = threading.Lock()  # held by the thread while it encodes the buffer
        self._ready = threading.Event()
        self._closed = False
        self.skipped = 0
        self._thread = threading.Thread(target=self._run, name="led-stream", daemon=True)
        self._thread.start()

    def offer(self, frame: int, t: float, values: np.ndarray | None) -> None:
        """Called by the frame loop after each frame: cheap, never blocks."""
        if values is None or frame % self.every:
            return
        if not self._busy.acquire(blocking=False):
            self.skipped += 1
            return
        try:
            if self._buf is None or self._buf.shape != values.shape:
                self._buf = np.empty_like(values)
            np.copyto(self._buf, values)
            self._meta = (frame, t, time.time())
        finally:
            self._busy.release()
        self._ready.set()

    def _run(self) -> None:
        while True:
            self._ready.wait()
            self._ready.clear()
            if self._closed:
                return
            with self._busy:
                payload = encode_leds(*self._meta, self._buf)
            try:
                self._pub.put(payload)
            except Exception as exc:  # noqa: BLE001 - whatever zenoh raises: the loop never hears of it
                if self._closed:  # the session closed at shutdown
                    return
                self.failed += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                if (self.failed - 1) % self.REPORT_EVERY == 0:
                    self._report(f"antarium serve: the LED stream's put failed ({self.failed} so far, the stream "
                                 f"goes on): {self.last_error}")

    def close(self) -> None:
        self._closed = True
        self._ready.set()
        self._thread.join(1.0)
        try:
            self._pub.undeclare()
        except Exception:  # noqa: BLE001 - a closed session has undeclared it already
            pass
