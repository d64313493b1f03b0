"""Locomotion from the bus: subscribes to `antarium/<rig>/locomotion` (44-byte `antarium.locomotion.wire`
structs), so a trackball driver on another computer or a simulated ant can drive the loop.

Each sample is stamped with this process's clock when it arrives (clocks of different computers are never
compared). Malformed payloads (wrong size or version, unknown flag bits, a non-zero reserved field, a
non-finite number) are counted and dropped; samples dropped because `read()` fell `max_pending` behind are
counted (`dropped_samples`); a jump of the u32 sequence number (wrapping at 2**32) is counted as a gap (`gaps`,
`lost_samples`), a step back (or the same number again: more than 2**31 ahead) as a reset (`seq_resets`).
`connected` is False when no sample arrived for `timeout_s` seconds after one did (publisher gone), so the
loop holds the pose until samples come back.

A device driver on another computer also reports on `antarium/<rig>/events` (JSON with "event" and
"source", e.g. the USB trackball's "locomotion_lost" at an unplug): such a "locomotion_lost" makes
`connected` False at once, without waiting for `timeout_s`; "locomotion_back" / "locomotion_connected" or
the next sample clear it. Samples and events travel apart (each subscription has its own zenoh thread), so the
last samples published before the loss may arrive after its event: when the event names the sequence number of
the driver's last sample (`last_seq`), samples up to that one do not clear it. The server's own events (JSON
with "kind") are ignored.
"""

from __future__ import annotations

from typing import Any

from antarium.core.clock import Clock, MonotonicClock
from antarium.locomotion import BufferedSource, positive, wire
from antarium.locomotion.trackball.protocol import seq_gap


class BusSource(BufferedSource):
    """rig: the rig name; bus: a `[bus]` section (client role: connects to the server's endpoints)
    or session: an open zenoh session to share (not closed by `stop`)."""

    def __init__(self, rig: str = "rig1", bus: dict | None = None, session=None, timeout_s: float = 0.5,
                 max_pending: int = 100000, clock: Clock | None = None) -> None:
        from antarium.bus import check_rig_name

        self.rig_name = check_rig_name(rig)
        self.bus_section = bus
        self.clock = clock or MonotonicClock()
        self.timeout_s = positive(timeout_s, "bus source timeout_s", "s without samples before it is not connected")
        self._session = session
        self._own_session = session is None
        super().__init__(max_pending, "bus source max_pending")
        self._sub = None
        self._events_sub = None
        self._device_lost = False
        self._last_seq: int | None = None  # the newest sample's sequence number
        self._straggler_seq: int | None = None  # the driver's last sample before a loss, not arrived yet
        self.received = 0
        self.malformed = 0
        self.dropped_samples = 0  # the oldest waiting sample dropped: read() fell max_pending behind
        self.gaps = 0  # jumps of the sequence number (u32, wrapping): samples lost before they arrived
        self.lost_samples = 0
        self.seq_resets = 0  # steps back of the sequence number
        self.last_error = ""
        self._last_t: float | None = None

    def use_session(self, session) -> None:
        """Subscribe through `session` (e.g. the server's own) instead of opening one; call before `start`."""
        if self._sub is not None:
            raise RuntimeError("use_session must be called before start()")
        self._session, self._own_session = session, False

    def start(self) -> None:
        from antarium.bus import events_key, locomotion_key, open_session

        if self._sub is not None:
            return
        if self._session is None:
            self._session = open_session(self.bus_section, role="client")
        self._sub = self._session.declare_subscriber(locomotion_key(self.rig_name), self._on_sample)
        self._events_sub = self._session.declare_subscriber(events_key(self.rig_name), self._on_event)

    def _on_sample(self, sample) -> None:  # zenoh thread: keep it short
        t = self.clock.now()
        try:
            decoded = wire.decode(sample.payload.to_bytes(), t)
        except wire.LocomotionWireError as exc:
            with self._lock:
                self.malformed += 1
                self.last_error = str(exc)
            return
        dropped = self._push(decoded)
        with self._lock:
            self.received += 1
            if dropped:
                self.dropped_samples += 1
            gap = seq_gap(self._last_seq, decoded.seq)
            if gap >= 1 << 31:  # a step back (or the same number again): the publisher restarted
                self.seq_resets += 1
            elif gap:
                self.gaps += 1
                self.lost_samples += gap
            self._last_t = t
            self._last_seq = decoded.seq
            if self._straggler_seq is None:
                self._device_lost = False
            elif decoded.seq == self._straggler_seq:  # published before the loss: the next one is from after it
                self._straggler_seq = None

    def _on_event(self, sample) -> None:  # zenoh thread
        from antarium.bus import json_object

        event = json_object(sample.payload.to_bytes())
        if event is None or "source" not in event:
            return
        kind = event.get("event")
        with self._lock:
            if kind == "locomotion_lost":
                self._device_lost = True
                self.last_error = f"{event['source']} reports locomotion_lost: {event.get('reason', '')}".strip()
                last_seq = event.get("last_seq")
                if isinstance(last_seq, int) and not isinstance(last_seq, bool):
                    last_seq &= 0xFFFFFFFF  # as the wire carries it
                    self._straggler_seq = None if last_seq == self._last_seq else last_seq  # arrived already?
                else:
                    self._straggler_seq = None
            elif kind in ("locomotion_back", "locomotion_connected"):
                self._device_lost = False
                self._straggler_seq = None

    def lost_hint(self) -> str:
        from antarium.bus import locomotion_key

        return (f"is `antarium trackball` (or a simulated ant) running for rig {self.rig_name!r} and publishing on "
                f"{locomotion_key(self.rig_name)}?")

    def status(self) -> dict[str, Any]:
        with self._lock:
            last = self._last_t
            connected = not self._device_lost and (last is None or self.clock.now() - last <= self.timeout_s)
            return {"connected": connected, "received": self.received, "malformed": self.malformed,
                    "dropped_samples": self.dropped_samples, "gaps": self.gaps, "lost_samples": self.lost_samples,
                    "seq_resets": self.seq_resets, "last_error": self.last_error}

    def stop(self) -> None:
        for sub in (self._sub, self._events_sub):
            if sub is not None:
                sub.undeclare()
        self._sub = self._events_sub = None
        if self._own_session and self._session is not None:
            self._session.close()
            self._session = None
