"""What the monitor has heard from the rig's bus: newest LED frame, pose path, stats, status, events, liveliness.

Zenoh callbacks (their own threads) store under one lock; the web server takes what is new at its update rate.
LED payloads that are not this version's dome frames are dropped here (counted), never forwarded to a page. The path
starts anew when the rig comes back after its liveliness token went (a restarted server) or its poses' time or frame
number goes backwards: a page is sent `path_reset` and the new path.
"""

from __future__ import annotations

import threading
import time
from typing import Any

from antarium import bus
from antarium.monitor.led_stream import decode_leds, led_key

#: poses kept for a page opened later (the path's history), newest last
PATH_HISTORY = 20000
#: pose stream decimation for the path (frames): the dome's 190 Hz path drawn at about 38 Hz
PATH_EVERY = 5


class Hub:
    """Subscriptions to rig `rig` on an open zenoh `session`."""

    def __init__(self, session, rig: str) -> None:
        self.rig = rig
        self._lock = threading.Lock()
        self.leds: bytes | None = None
        self.leds_seq = 0
        self.leds_dropped = 0  # payloads that were not LED frames of this version and the dome's size
        self.leds_error: str | None = None  # why the last of them was dropped
        self.path: list[list[float]] = []  # [t, x, y, heading, scene_rotation, flags]
        self.path_seq = 0  # poses appended so far
        self.path_run = 0  # paths started anew so far (a restarted rig, time going backwards)
        self._rig_gone = False  # the liveliness token went: the next pose starts a new path
        self.pose: dict[str, Any] | None = None
        self.stats: list[dict[str, Any]] = []
        self.stats_seq = 0
        self.status: dict[str, Any] | None = None
        self.status_seq = 0
        self.events: list[dict[str, Any]] = []
        self.events_seq = 0
        self.alive = False
        self.alive_seq = 0
        self.trial: dict[str, Any] | None = None  # the running trial's name, metadata, start time (server clock)
        self._subs = [
            session.declare_subscriber(led_key(rig), self._on_leds),
            session.declare_subscriber(bus.pose_key(rig), self._on_pose),
            session.declare_subscriber(bus.stats_key(rig), self._on_stats),
            session.declare_subscriber(bus.status_key(rig), self._on_status),
            session.declare_subscriber(bus.events_key(rig), self._on_event),
            session.liveliness().declare_subscriber(bus.alive_key(rig), self._on_alive, history=True),
        ]

    def close(self) -> None:
        for sub in self._subs:
            try:
                sub.undeclare()
            except Exception:  # noqa: BLE001 - a closed session has undeclared them already
                pass

    def _on_leds(self, sample) -> None:
        payload = sample.payload.to_bytes()
        try:
            decode_leds(payload)
        except bus.StreamError as exc:
            with self._lock:
                self.leds_dropped += 1
                self.leds_error = str(exc)
            return
        with self._lock:
            self.leds = payload
            self.leds_seq += 1

    def _on_pose(self, sample) -> None:
        try:
            p = bus.decode_pose(sample.payload.to_bytes())
        except bus.StreamError:
            return
        with self._lock:
            last, self.pose = self.pose, p
            if self._rig_gone or (last is not None and (p["t"] < last["t"] or p["frame"] < last["frame"])):
                self._rig_gone = False  # a new run: its path is not joined to the last one's
                self.path = []
                self.path_run += 1
            if p["frame"] % PATH_EVERY == 0:
                flags = (1 if p["closed_loop"] else 0) | (2 if p["fixed_tether"] else 0)
                self.path.append([p["t"], p["x"], p["y"], p["heading"], p["scene_rotation"], flags])
                self.path_seq += 1
                if len(self.path) > PATH_HISTORY:
                    del self.path[: len(self.path) - PATH_HISTORY]

    def _on_stats(self, sample) -> None:
        try:
            s = bus.decode_stats(sample.payload.to_bytes())
        except bus.StreamError:
            return
        s["t_wall"] = time.time()
        with self._lock:
            self.stats.append(s)
            self.stats_seq += 1
            del self.stats[:-600]

    def _on_status(self, sample) -> None:
        status = bus.json_object(sample.payload.to_bytes())
        if status is None:
            return
        with self._lock:
            self.status = status
            self.status_seq += 1
            name = status.get("trial")
            if name is None:
                self.trial = None
            elif self.trial is None or self.trial["name"] != name:  # started before the monitor subscribed
                started = status.get("trial_started") if isinstance(status.get("trial_started"), dict) else {}
                self.trial = {"name": name, "metadata": started.get("metadata"), "t_start": started.get("t")}

    def _on_event(self, sample) -> None:
        event = bus.json_object(sample.payload.to_bytes())
        if event is None:
            return
        data = event.get("data") if isinstance(event.get("data"), dict) else {}
        with self._lock:
            if event.get("kind") == "trial_started":
                self.trial = {"name": data.get("name"), "metadata": data.get("metadata"),
                              "t_start": data.get("monotonic", event.get("t"))}  # the status's trial_started "t"
            elif event.get("kind") == "trial_stopped":
                self.trial = None
            self.events.append(event)
            self.events_seq += 1
            del self.events[:-200]

    def _on_alive(self, sample) -> None:
        import zenoh

        with self._lock:
            self.alive = sample.kind == zenoh.SampleKind.PUT
            self.alive_seq += 1
            if not self.alive and self.pose is not None:
                self._rig_gone = True

    def since(self, seen: dict[str, int], leds: bool = True) -> tuple[bytes | None, dict[str, Any]]:
        """(the newest LED payload if not seen and `leds`, JSON-able updates not seen); `seen` is updated."""
        with self._lock:
            leds = self.leds if leds and self.leds_seq != seen.get("leds", 0) else None
            if leds is not None:
                seen["leds"] = self.leds_seq
            out: dict[str, Any] = {}
            new_path = self.path_seq - seen.get("path", 0)
            if seen.get("path_run") != self.path_run:  # a new page, or a new path: all of it, drawn anew
                out["path_reset"] = True
                out["path"] = list(self.path)
                seen["path"], seen["path_run"] = self.path_seq, self.path_run
            elif new_path:
                out["path"] = self.path[-min(new_path, len(self.path)):]
                seen["path"] = self.path_seq
            for name in ("stats", "events"):
                new = getattr(self, f"{name}_seq") - seen.get(name, 0)
                if new:
                    items = getattr(self, name)
                    out[name] = items[-min(new, len(items)):]
                    seen[name] = getattr(self, f"{name}_seq")
            if self.status_seq != seen.get("status", 0):
                out["status"] = self.status
                out["trial"] = self.trial
                seen["status"] = self.status_seq
            if self.alive_seq != seen.get("alive", 0) or "alive" not in seen:
                out["alive"] = self.alive
                seen["alive"] = self.alive_seq
            if self.pose is not None and out.get("path") is not None:
                out["pose"] = self.pose
            if self.leds_dropped != seen.get("leds_dropped", 0):
                out["leds_dropped"] = {"count": self.leds_dropped, "error": self.leds_error}
                seen["leds_dropped"] = self.leds_dropped
        return leds, out
