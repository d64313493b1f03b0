"""The frame loop: paced frames on an injected clock, closed or open loop, per-frame measurements.

Each `step()`: run the commands queued by other threads, wait for the frame's slot, take the newest
locomotion samples, update the virtual pose (closed loop), render the LED frame, send it (and the latch)
over the link, measure, log and publish. A frame whose sending ends after its slot (`t_target + period`)
is counted late; slots that have passed meanwhile are skipped, never queued, so lag cannot accumulate.

Everything is injected: `clock` (`antarium.core.clock`), `source` (`antarium.locomotion`), `renderer`
(`antarium.renderers.Renderer`, or None for pose-only runs), `link` (`antarium.firmware_proto` link, or
None), `log` (`antarium.trial_log.TrialLog`, or None). With a `SimulatedClock` the same code runs faster
than real time (tests, the virtual ant):

    loop = FrameLoop(clock=SimulatedClock(), source=src, renderer=r, link=open_link("virtual"))
    loop.step()                      # one frame
    loop.run(until=10.0)             # frames until the clock reads 10 s

Pose conventions (SI, radians): `pose.heading` is the world azimuth of the dome's +x axis. Tether
"free_yaw": the ant turns on its pin, the ball gives translation in the dome frame, the heading changes only
by command. Tether "fixed": the ball gives yaw too, the heading turns with the ant (the scene rotates).
Rotating the scene by +a (counter-clockwise, as the ant sees it) turns the heading by -a.

A control change (set_pose, reset_origin, rotate_scene, closed loop, tether, gains; any `call_soon` command) applies
when it runs, between frames: the samples that arrived before it move the pose first, under the state before it, so
the next frame shows a pose set or reset exactly, and motion walked in open loop never moves it. Those samples are
the next frame's (its `sample_seq`, `latency`, the log's locomotion rows).
"""

from __future__ import annotations

import concurrent.futures
import math
import queue
import threading
from collections.abc import Callable
from dataclasses import dataclass, fields
from operator import attrgetter
from typing import TYPE_CHECKING, Any

import numpy as np

from antarium.core.ball import BALL_RADIUS_M, arc_step, check_tether, pole_motion
from antarium.core.clock import Clock
from antarium.core.pose import Pose
from antarium.core.rates import DOME_RATE_HZ
from antarium.firmware_proto.budget import DEFAULT_LINK_BPS, LinkBudget, max_frame_rate
from antarium.firmware_proto.polariser import wrap_angles
from antarium.locomotion import LocomotionSource
from antarium.trial_log import FRAME_DTYPE

if TYPE_CHECKING:
    from antarium.config import LoopSection

#: how many recent frames the statistics (percentiles, frame rate) cover
STATS_WINDOW = 2048
#: ask the locomotion source whether it is connected every this many frames
LOCOMOTION_CHECK_EVERY = 10
#: ask the distributor for telemetry this often (s); the link is down when the newest reply is older than
#: LINK_TIMEOUT_S, or when datagrams failed (peer refused: the distributor or emulator is gone; send buffer full) at
#: every poll for LINK_FAILING_S: a failure that does not last (one full send buffer) is only counted
TELEMETRY_EVERY_S = 0.1
LINK_TIMEOUT_S = 0.5
LINK_FAILING_S = 0.5
#: the link is down from the start until the distributor answers; one that has not answered this long after the
#: first frame (or by the end of a shorter run) counts as an outage
LINK_STARTUP_S = 5.0
#: locomotion_lost / locomotion_back events: at most one per this many seconds (the state itself is exact at once)
LOCOMOTION_EVENT_EVERY_S = 1.0
#: `when_idle` work runs after a frame only when at least this much time (s) is left before the next slot
IDLE_MARGIN_S = 2.5e-3
#: with keep_gpu_busy, the GPU's busy work stops this long (s) before a frame's slot
GPU_BUSY_MARGIN_S = 0.5e-3


@dataclass(frozen=True, slots=True)
class FrameRecord:
    """What happened in one frame (times in seconds on the loop's clock; NaN when not measured)."""

    frame: int
    t_target: float
    t_start: float
    t_sent: float
    pose: Pose
    scene_rotation: float
    closed_loop: bool
    fixed_tether: bool
    sample_seq: int  # newest locomotion sequence number used, -1 when none arrived this frame
    latency: float  # newest sample's arrival -> last datagram sent; NaN when no sample arrived
    render: float
    sample: float
    convert: float
    encode: float
    send: float
    pacing_error: float  # t_start - t_target
    late: bool
    skipped: int  # frame slots skipped after this frame because it overran
    locomotion_connected: bool
    link_ok: bool
    full_render: bool  # every mesh drawn this frame (the renderer's slow path: no far layer in use)

    def log_row(self) -> tuple:
        """The record in `antarium.trial_log.FRAME_DTYPE`'s field order (the pose's fields from `pose`)."""
        return _LOG_ROW(self)


POSE_FIELDS = {f.name for f in fields(Pose)}
#: FRAME_DTYPE's fields read from a FrameRecord: the log's layout is the one table, the row follows it
_LOG_ROW = attrgetter(*(f"pose.{name}" if name in POSE_FIELDS else name for name in FRAME_DTYPE.names))


class LoopClosed(RuntimeError):
    """A call handed to a frame loop that will run no more frames (`FrameLoop.refuse_calls`): it was not run."""


def _check_gain(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or not -100.0 <= value <= 100.0:
        raise ValueError(f"{name} must be a finite number in [-100, 100], got {value!r}")
    return float(value)


class FrameLoop:
    """Paced frames; see the module docstring. Control methods run in the loop's thread (or through
    `call_soon` from others); they validate first and leave the state unchanged on a ValueError."""

    @classmethod
    def from_config(cls, loop: LoopSection, **parts: Any) -> FrameLoop:
        """The frame loop a `[loop]` section describes; `parts`: clock, source, renderer, link, log, on_frame,
        on_event (the server's rig and the virtual ant's both assemble their loop here)."""
        origin = Pose(loop.start_x_m, loop.start_y_m, loop.eye_height_m, math.radians(loop.start_heading_deg))
        return cls(rate_hz=loop.rate_hz, closed_loop=loop.closed_loop, tether=loop.tether,
                   gain_translation=loop.gain_translation, gain_rotation=loop.gain_rotation, origin=origin,
                   ball_radius=loop.ball_radius_m, keep_gpu_busy=loop.keep_gpu_busy, **parts)

    def __init__(self, *, clock: Clock, source: LocomotionSource | None, renderer=None, link=None,
                 rate_hz: float = DOME_RATE_HZ, closed_loop: bool = True, tether: str = "free_yaw",
                 gain_translation: float = 1.0, gain_rotation: float = 1.0, origin: Pose | None = None,
                 ball_radius: float = BALL_RADIUS_M, keep_gpu_busy: bool | str = "auto", log=None,
                 link_bps: float = DEFAULT_LINK_BPS,
                 on_frame: Callable[[FrameRecord], None] | None = None,
                 on_event: Callable[[float, str, dict], None] | None = None) -> None:
        if not isinstance(rate_hz, (int, float)) or not 1.0 <= rate_hz <= 2000.0:
            raise ValueError(f"rate_hz must be in [1, 2000] frames/s, got {rate_hz!r}")
        check_tether(tether)
        self.clock, self.source, self.renderer, self.link = clock, source, renderer, link
        self.period = 1.0 / float(rate_hz)
        self.rate_hz = float(rate_hz)
        self.closed_loop = bool(closed_loop)
        self.tether = tether
        self.gain_translation = _check_gain("gain_translation", gain_translation)
        self.gain_rotation = _check_gain("gain_rotation", gain_rotation)
        self.origin = origin or Pose()
        self.pose = self.origin
        self.scene_rotation = 0.0
        self.ball_radius = float(ball_radius)
        if keep_gpu_busy not in (True, False, "auto"):
            raise ValueError(f'keep_gpu_busy must be true, false or "auto", got {keep_gpu_busy!r}')
        self.keep_gpu_busy = keep_gpu_busy
        self.gpu_busy_passes = 0
        self.log = log
        self.on_frame = on_frame
        self.on_event = on_event
        self.frame = 0
        self.late_frames = 0
        self.skipped_frames = 0
        self.samples_used = 0
        self._caught_up: list = []  # samples read by `_catch_up` since the last frame, in order
        self._caught_up_log = None  # the log they went into (a trial started or stopped between frames changes it)
        self.locomotion_connected = True
        self.locomotion_losses = 0  # how often the source was lost (read() raising, or status() not connected)
        self._loco_reported = True  # the state the last locomotion event told
        self._loco_status: dict = {}
        #: while the source is lost: (its last sample's seq as its status named it, or None; when the loop saw it)
        self._loss: tuple[int | None, float] | None = None
        self._loco_changes = 0  # state changes since the last locomotion event
        self._last_loco_event_t = -math.inf
        self.link_ok = link is None  # a link is down until the distributor has answered
        self.link_outages = 0
        self.last_link_error = "" if link is None else "the distributor has not answered yet"
        self._unanswered_reported = False
        self._next_t: float | None = None
        self._frame_buf = None
        self._pending: queue.SimpleQueue = queue.SimpleQueue()
        self._idle: queue.SimpleQueue = queue.SimpleQueue()
        self._refusal: str | None = None  # why calls are refused (`refuse_calls`); None: they are taken
        self._stop = threading.Event()
        self._loop_thread: threading.Thread | None = None
        # per recent frame: t_start, latency, render, sample, convert, encode, send, pacing error (s)
        self._stats = np.full((STATS_WINDOW, 8), np.nan)
        self.polariser_override = None
        self.rejected_frames = 0
        self._last_reject_event_t = -math.inf
        self.faults: dict[str, int] = {}
        self.last_fault: dict[str, tuple[float, str]] = {}  # per part: when it last failed (loop clock), and how
        self._source_failing = False
        self._last_fault_event_t: dict[str, float] = {}
        self._last_late_event_t = -math.inf
        self._late_since_event = 0
        self._worst_overrun = 0.0
        self.telemetry: dict[str, Any] = {}
        self._next_telemetry_t = -math.inf
        self._last_poll_t: float | None = None
        self._failed_datagrams = 0
        self._failing_since: float | None = None  # the first poll of the polls in a row that saw failed datagrams
        self.transient_link_failures = 0  # polls that saw failed datagrams without an outage
        self._t_first: float | None = None
        self._polariser_heading: float | None = None
        #: the dome link's bit budget at `link_bps` bits/s (None where the frames alone exceed it: nothing to share)
        self.link_budget = LinkBudget(rate_hz, link_bps) if rate_hz <= max_frame_rate(link_bps) else None
        #: the link's `state_resent_bits` the budget has counted (a link may have resent under an earlier loop)
        self._resent_bits = getattr(link, "counters", {}).get("state_resent_bits", 0)
        self._polarisers_dirty = False
        self._sky_present = False
        if renderer is not None:
            self.renderer_changed()

    # -- events and commands ---------------------------------------------------------------------------
    def event(self, kind: str, **data: Any) -> None:
        """Record an event in the log and hand it to `on_event` (the server publishes it)."""
        t = self.clock.now()
        if self.log is not None:
            self.log.add_event(t, kind, data)
        if self.on_event is not None:
            self.on_event(t, kind, data)

    def call_soon(self, fn: Callable, *args: Any, **kwargs: Any) -> concurrent.futures.Future:
        """Run `fn(*args, **kwargs)` in the loop's thread before the next frame; thread-safe. After `refuse_calls`,
        the future fails at once with `LoopClosed`."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        self._pending.put((future, fn, args, kwargs))
        if self._refusal is not None:
            self._refuse_queued()
        return future

    def when_idle(self, fn: Callable, *args: Any, **kwargs: Any) -> concurrent.futures.Future:
        """Run `fn(*args, **kwargs)` in the loop's thread after a frame that leaves IDLE_MARGIN_S before the next
        slot, one such call per frame; thread-safe. For housekeeping (status, CPU placement) that would
        otherwise take the GIL from the frame in another thread. After `refuse_calls`, the future fails at once with
        `LoopClosed`."""
        future: concurrent.futures.Future = concurrent.futures.Future()
        self._idle.put((future, fn, args, kwargs))
        if self._refusal is not None:
            self._refuse_queued()
        return future

    def refuse_calls(self, reason: str) -> None:
        """The loop will run no more frames (its owner shuts down): every call queued and not run, and every later
        `call_soon` or `when_idle`, fails at once with `LoopClosed(reason)` instead of waiting for a frame that
        never comes. Thread-safe: a call queued while this runs is failed by this or by its own `call_soon`."""
        self._refusal = reason
        self._refuse_queued()

    def _refuse_queued(self) -> None:
        for calls in (self._pending, self._idle):
            while True:
                try:
                    future = calls.get_nowait()[0]
                except queue.Empty:
                    break
                if future.set_running_or_notify_cancel():
                    future.set_exception(LoopClosed(self._refusal))

    def _run_pending(self, calls: queue.SimpleQueue | None = None, limit: int | None = None) -> None:
        calls = self._pending if calls is None else calls
        while limit is None or limit > 0:
            try:
                future, fn, args, kwargs = calls.get_nowait()
            except queue.Empty:
                return
            if limit is not None:
                limit -= 1
            if not future.set_running_or_notify_cancel():
                continue
            caught_up = False
            try:
                if calls is self._pending:  # a command reads the state as it is now (the pose after the samples so far)
                    self._catch_up()
                caught_up = True
                future.set_result(fn(*args, **kwargs))
            except BaseException as exc:  # handed to the caller, who replies with the error
                future.set_exception(exc)
                if not caught_up:  # the samples before it end the loop, as they would in the next frame
                    raise

    # -- control (loop thread) -------------------------------------------------------------------------
    def set_pose(self, pose: Pose) -> None:
        """Virtual displacement: put the eye at `pose` now (heading = world azimuth of the dome's +x)."""
        if not isinstance(pose, Pose):
            raise ValueError(f"set_pose needs an antarium.core.pose.Pose, got {type(pose).__name__}")
        self._catch_up()
        self.pose = pose
        self.event("pose_set", x=pose.x, y=pose.y, z=pose.z, heading=pose.heading)

    def reset_origin(self, origin: Pose | None = None) -> None:
        """Put the eye back at the virtual origin (or make `origin` the new origin and go there)."""
        if origin is not None and not isinstance(origin, Pose):
            raise ValueError(f"reset_origin needs an antarium.core.pose.Pose or None, got {type(origin).__name__}")
        self._catch_up()
        self.origin = origin or self.origin
        self.pose = self.origin
        self.scene_rotation = 0.0
        o = self.origin
        self.event("origin_reset", x=o.x, y=o.y, z=o.z, heading=o.heading)

    def rotate_scene(self, angle: float) -> None:
        """Rotate the scene instantly by `angle` rad, counter-clockwise as seen from above."""
        if isinstance(angle, bool) or not isinstance(angle, (int, float)) or not math.isfinite(angle):
            raise ValueError(f"scene rotation must be a finite angle in radians, got {angle!r}")
        self._catch_up()
        self.scene_rotation = math.remainder(self.scene_rotation + angle, math.tau)
        self.pose = self.pose.moved(dheading=-angle)
        self.event("scene_rotated", angle=float(angle), total=self.scene_rotation)

    def set_closed_loop(self, on: bool) -> None:
        if not isinstance(on, bool):
            raise ValueError(f"closed_loop must be true or false, got {on!r}")
        self._catch_up()
        self.closed_loop = on
        self.event("closed_loop", on=on)

    def set_tether(self, tether: str) -> None:
        check_tether(tether)
        self._catch_up()
        self.tether = tether
        self.event("tether", tether=tether)

    def set_gains(self, translation: float | None = None, rotation: float | None = None) -> None:
        t = self.gain_translation if translation is None else _check_gain("gain translation", translation)
        r = self.gain_rotation if rotation is None else _check_gain("gain rotation", rotation)
        self._catch_up()
        self.gain_translation, self.gain_rotation = t, r
        self.event("gains", translation=t, rotation=r)

    def renderer_changed(self) -> None:
        """Call after changing the renderer's scene or sky: the polariser angles are sent with the next frame."""
        self._polarisers_dirty = True
        scene = getattr(self.renderer, "scene", None)
        self._sky_present = getattr(scene, "sky", None) is not None

    def set_polarisers(self, angles) -> None:
        """Hold the polarisers at `angles` (55, 9) rad, or None to follow the scene's sky again."""
        if angles is not None:
            angles = np.asarray(angles, dtype=np.float64)
            if angles.shape != (55, 9) or not np.all(np.isfinite(angles)):
                raise ValueError(f"polariser angles must be (55, 9) finite radians, got shape {angles.shape}")
            angles = wrap_angles(angles)  # into [0, pi): a tiny negative angle is 0, not pi
        self.polariser_override = angles
        self._polarisers_dirty = True
        self.event("polarisers", mode="sky" if angles is None else "fixed")

    # -- the frame -------------------------------------------------------------------------------------
    def _integrate(self, samples, t: float) -> None:
        """Move the pose by the samples' ball rotations; a sample that would make it non-finite (a NaN or an
        absurd rotation from a source) is skipped and counted as a locomotion fault, never ends the loop."""
        x, y, heading = self.pose.x, self.pose.y, self.pose.heading
        gt, gr, fixed = self.gain_translation, self.gain_rotation, self.tether == "fixed"
        skipped = 0
        for s in samples:
            dx, dy, dyaw = pole_motion(s.rotation, self.ball_radius)
            wx, wy, h = arc_step(heading, gt * dx, gt * dy, gr * dyaw if fixed else 0.0)
            nx, ny = x + wx, y + wy
            if not (math.isfinite(nx) and math.isfinite(ny) and math.isfinite(h)):
                skipped += 1
                continue
            x, y, heading = nx, ny, h
        if skipped:
            self.fault("locomotion", t, ValueError(f"{skipped} sample(s) skipped: a rotation that is not a finite "
                                                   "number of radians"))
        self.pose = Pose(x, y, self.pose.z, math.remainder(heading, math.tau))

    def _before_loss(self, samples) -> list:
        """Of `samples` read while the source is lost, those it measured before the loss (its driver queued them
        before it noticed the unplug; the pose moves by them as the log says), the rest held: up to the one with
        the sequence number the source's status named as its last (`last_seq`), else (none named, or not read
        yet) those that arrived by the time the loop saw the loss (`t` on the loop's clock, which the server
        gives every source)."""
        loss = self._loss
        if loss is None:
            return []
        last_seq, t_lost = loss
        if last_seq is not None:
            for k, s in enumerate(samples):
                if s.seq == last_seq:
                    self._loss = None  # everything after it was measured after the loss
                    return samples[:k + 1]
        return [s for s in samples if s.t <= t_lost]

    def _check_locomotion(self, now: float) -> None:
        """The source says whether it is connected (a USB trackball unplugged): hold the pose while it is not."""
        if self.source is not None:
            try:
                status = self.source.status()
                if not isinstance(status, dict):
                    raise TypeError(f"status() returned {type(status).__name__}, not a dict")
                connected = bool(status.get("connected", True))
            except Exception as exc:  # noqa: BLE001 - a failing status is a failing source
                self.fault("locomotion", now, exc)
                status = {"connected": False, "error": f"{type(exc).__name__}: {exc}"}
                connected = False
            connected = connected and not self._source_failing
            if connected != self.locomotion_connected:
                self._locomotion_changed(now, connected, status)

    def _locomotion_changed(self, t: float, connected: bool, status: dict) -> None:
        """The source was lost or came back: the state changes now (status, the frames' log rows); the event
        follows at most once every LOCOMOTION_EVENT_EVERY_S (a flaky source would flood the bus and stderr)."""
        self.locomotion_connected = connected
        if not connected:
            self.locomotion_losses += 1
            last_seq = status.get("last_seq")
            self._loss = (last_seq if isinstance(last_seq, int) and not isinstance(last_seq, bool) else None, t)
        else:
            self._loss = None
        self._loco_status = status
        self._loco_changes += 1
        self._report_locomotion(t)

    def _report_locomotion(self, t: float, now: bool = False) -> None:
        """A locomotion_lost / locomotion_back event when the state differs from the last one told and the last
        event is LOCOMOTION_EVENT_EVERY_S old (`now`: at once): `losses` so far, `changes` since the last event
        (1 unless changes were held back)."""
        connected = self.locomotion_connected
        if connected == self._loco_reported or (not now and t - self._last_loco_event_t < LOCOMOTION_EVENT_EVERY_S):
            return
        self._loco_reported, self._last_loco_event_t = connected, t
        changes, self._loco_changes = self._loco_changes, 0
        self.event("locomotion_back" if connected else "locomotion_lost", status=self._loco_status,
                   losses=self.locomotion_losses, changes=changes)

    def _check_link(self, now: float) -> None:
        """Poll the distributor's telemetry every TELEMETRY_EVERY_S; report outages and recoveries.

        The newest reply can only answer the previous poll, so the link is down when that reply is older than
        LINK_TIMEOUT_S plus the time since the previous poll (a slow loop polls less often), or datagrams failed
        at every poll for LINK_FAILING_S (a shorter run of failures is counted in `transient_link_failures`).
        """
        if self.link is None or now < self._next_telemetry_t:
            return
        since_poll = now - self._last_poll_t if self._last_poll_t is not None else 0.0
        self._last_poll_t = now
        self._next_telemetry_t = now + TELEMETRY_EVERY_S
        self.telemetry = self.link.telemetry()
        failed = self.telemetry.get("link", {}).get("datagrams_failed", 0)
        new_failures, self._failed_datagrams = failed - self._failed_datagrams, failed
        age = self.telemetry.get("age_s")
        if age is None:  # not answered yet: down from the start; an outage once it had LINK_STARTUP_S to come up
            if now - self._t_first >= LINK_STARTUP_S:
                self._report_unanswered(now)
            return
        fresh = age <= LINK_TIMEOUT_S + since_poll
        if not new_failures:
            self._failing_since = None
        elif self._failing_since is None:
            self._failing_since = now
        failing = self._failing_since is not None and now - self._failing_since >= LINK_FAILING_S
        if new_failures and not failing and self.link_ok:
            self.transient_link_failures += 1
        ok = fresh and not failing
        if failing:
            self.last_link_error = (f"datagrams failed for {now - self._failing_since:.2f} s (peer refused or "
                                    "send buffer full)")
        elif not fresh:
            self.last_link_error = f"no telemetry from the distributor for {age:.2f} s"
        if ok != self.link_ok:
            self.link_ok = ok
            if not ok:
                self.link_outages += 1
            first = ok and self.link_outages == 0
            self.event("link_up" if first else "link_back" if ok else "link_outage",
                       error="" if ok else self.last_link_error)

    def _report_unanswered(self, now: float) -> None:
        """The distributor never answered since the first frame: count one outage (once)."""
        if self.link is None or self.link_ok or self._unanswered_reported or self._t_first is None \
                or self.telemetry.get("age_s") is not None:
            return
        self._unanswered_reported = True
        self.link_outages += 1
        self.last_link_error = f"the distributor has not answered in {now - self._t_first:.2f} s"
        self.event("link_outage", error=self.last_link_error)

    def _take_samples(self, t: float) -> list:
        """Read the source's new samples at `t` (s, loop clock), log them and move the pose by them (closed loop,
        source connected); returns them."""
        samples = self._read_source(t)
        if samples:
            self.samples_used += len(samples)
            if self.log is not None:
                self.log.add_samples(samples)
            if not self.locomotion_connected and not self._source_failing:
                self._check_locomotion(t)  # samples again: a replugged source is taken at once
            moved = samples if self.locomotion_connected else self._before_loss(samples)
            if self.closed_loop and moved:
                self._integrate(moved, t)
        return samples

    def _catch_up(self) -> None:
        """Before a control change between frames: the samples that arrived so far were measured under the old
        state (pose, mode, tether, gains) and move the pose by it; the next frame's record counts them."""
        if self._t_first is not None:  # before the first frame the source may not be started: the frame reads it
            if self.log is not self._caught_up_log:  # those read so far went into another log (or none)
                self._caught_up, self._caught_up_log = [], self.log
            self._caught_up += self._take_samples(self.clock.now())

    def _read_source(self, t: float) -> list:
        """The source's new samples; a source that raises is reported as disconnected, never stops the loop."""
        if self.source is None:
            return []
        try:
            samples = self.source.read()
            self._source_failing = False
            return samples
        except Exception as exc:  # a driver bug must not end the trial
            self._source_failing = True
            self.fault("locomotion", t, exc)
            if self.locomotion_connected:
                self._locomotion_changed(t, False, {"error": f"{type(exc).__name__}: {exc}"})
            return []

    def fault(self, part: str, t: float, exc: Exception) -> None:
        """Count an exception of a part (render, locomotion, bus); an event at most once a second per part."""
        self.faults[part] = self.faults.get(part, 0) + 1
        self.last_fault[part] = t, f"{type(exc).__name__}: {exc}"
        if t - self._last_fault_event_t.get(part, -math.inf) >= 1.0:
            self._last_fault_event_t[part] = t
            self.event(f"{part}_error", error=f"{type(exc).__name__}: {exc}", count=self.faults[part])

    def _frame_rejected(self, t: float, reason: str) -> None:
        self.rejected_frames += 1
        if t - self._last_reject_event_t >= 1.0:  # at most one event a second, with the count so far
            self._last_reject_event_t = t
            self.event("frame_rejected", reason=reason, rejected_frames=self.rejected_frames)

    def _send_polarisers(self, pose: Pose) -> bool:
        """Polariser angles to the link, after the frame: a commanded override, or the sky's for this pose (when
        they change); deferred to a later period while the link has no room for them (`LinkBudget`)."""
        override = self.polariser_override is not None
        if not (self._polarisers_dirty or (not override and self._sky_present
                                           and pose.heading != self._polariser_heading)):
            return False
        if self.link_budget is not None and not self.link_budget.update_fits():
            self.link_budget.deferred += 1
            return False
        angles = self.polariser_override if override else self.renderer.polariser_angles()
        failed = self.link.counters["datagrams_failed"]
        try:
            sent = self.link.send_polarisers(angles)
            went_out = self.link.counters["datagrams_failed"] == failed
        except ValueError as exc:  # angles the link refuses: counted, the dome keeps its polarisers, frames go on
            self.fault("link", self.clock.now(), exc)
            sent = went_out = False
        # an update refused or failed to go out is tried again with the next frame (unchanged angles are not)
        self._polarisers_dirty = not went_out
        if went_out and not override:
            self._polariser_heading = pose.heading
        return sent

    @property
    def gpu_kept_busy(self) -> bool:
        """Whether the loop keeps the renderer's GPU busy between frames: `keep_gpu_busy`, where "auto" is on when
        the renderer's frame path runs on a hardware GPU and the clock is wall time (an idle GPU lowers its
        clocks, and a frame then takes several times as long on it; a simulated clock does not wait)."""
        if self.keep_gpu_busy == "auto":
            return bool(getattr(self.clock, "realtime", False) and getattr(self.renderer, "on_hardware_gpu", False))
        return self.keep_gpu_busy

    def _busy_gpu(self, until: float) -> None:
        """Keep the renderer's GPU busy until `until` (s on the loop's clock)."""
        busy = getattr(self.renderer, "keep_gpu_busy", None)
        if busy is not None:
            try:
                self.gpu_busy_passes += busy(self.clock, until)
            except Exception as exc:  # counted like a render error; the frame is still rendered
                self.fault("render", self.clock.now(), exc)

    def step(self) -> FrameRecord:
        """Run one frame (waiting for its slot on the clock) and return what happened."""
        self._run_pending()
        clock = self.clock
        if self._next_t is None:
            self._next_t = clock.now()
        t_target = self._next_t
        if self.renderer is not None and self.gpu_kept_busy:
            self._busy_gpu(t_target - GPU_BUSY_MARGIN_S)
        clock.sleep_until(t_target)
        t_start = clock.now()
        if self._t_first is None:
            self._t_first = t_start
        if self.frame % LOCOMOTION_CHECK_EVERY == 0:
            self._check_locomotion(t_start)
        self._check_link(t_start)
        caught_up = self._caught_up if self._caught_up_log is self.log else []  # a frames row names its log's samples
        samples, self._caught_up = caught_up + self._take_samples(t_start), []
        newest = samples[-1] if samples else None
        if self.locomotion_connected != self._loco_reported:  # a change held back: told once a second has passed
            self._report_locomotion(t_start)
        pose = self.pose
        render = sample = convert = encode = send = math.nan
        full_render = False
        if self.renderer is not None:
            try:
                self._frame_buf = self.renderer.render(pose, out=self._frame_buf)
                timings = getattr(self.renderer, "last_timings", None) or {}
                render = timings.get("render", math.nan)
                sample = timings.get("sample", math.nan)
                convert = timings.get("convert", math.nan)
                full_render = bool(getattr(self.renderer, "last_full_render", False))
            except Exception as exc:  # the dome keeps the previous frame; the loop, the log and the bus go on
                self.fault("render", t_start, exc)
        if self.link is not None and self._frame_buf is not None:
            t0 = clock.now()
            packed = getattr(self.renderer, "datagrams", None)  # packed on the GPU path: no encoding here
            try:
                if packed is not None:
                    self.link.send_packed(packed)
                else:
                    self.link.send_frame(self._frame_buf)
            except ValueError as exc:  # a frame breaking the LED-frame contract is not sent; the loop goes on
                self._frame_rejected(t0, str(exc))
            update_sent = False
            if self.renderer is not None and hasattr(self.renderer, "polariser_angles"):
                update_sent = self._send_polarisers(pose)
            if self.link_budget is not None:  # with the held state the link sent again this period (a reboot)
                resent = getattr(self.link, "counters", {}).get("state_resent_bits", 0)
                self.link_budget.period(update_sent, resent - self._resent_bits)
                self._resent_bits = resent
            t1 = clock.now()
            link_timings = getattr(self.link, "last_timings", None) or {}
            encode = link_timings.get("encode", math.nan)
            send = link_timings.get("send", t1 - t0)
        t_sent = clock.now()
        latency = t_sent - newest.t if newest is not None else math.nan
        slot_end = t_target + self.period
        late = t_sent > slot_end
        skipped = 0
        next_t = slot_end
        now = clock.now()
        if now > next_t:
            skipped = int((now - next_t) // self.period) + 1
            next_t += skipped * self.period
        self._next_t = next_t
        if late:
            self.late_frames += 1
        self.skipped_frames += skipped
        rec = FrameRecord(self.frame, t_target, t_start, t_sent, pose, self.scene_rotation, self.closed_loop,
                          self.tether == "fixed", newest.seq if newest is not None else -1, latency, render, sample,
                          convert, encode, send, t_start - t_target, late, skipped, self.locomotion_connected,
                          self.link_ok, full_render)
        self._stats[self.frame % STATS_WINDOW] = (t_start, latency, render, sample, convert, encode, send,
                                                  t_start - t_target)
        self.frame += 1
        if self.log is not None:
            self.log.add_frame(rec.log_row())
        if late:
            self._late_since_event += 1
            self._worst_overrun = max(self._worst_overrun, t_sent - slot_end)
        self._report_late(t_sent)
        if self.on_frame is not None:
            self.on_frame(rec)
        if self._next_t - clock.now() >= IDLE_MARGIN_S:
            self._run_pending(self._idle, limit=1)
        return rec

    def _report_late(self, t: float, now: bool = False) -> None:
        """A late_frames event for the late frames not told yet, when the last one is a second old (`now`: at once):
        `count` of them, the `total`, their `worst_overrun` (s), `skipped_total`."""
        if not self._late_since_event or (not now and t - self._last_late_event_t < 1.0):
            return
        self.event("late_frames", count=self._late_since_event, total=self.late_frames,
                   worst_overrun=self._worst_overrun, skipped_total=self.skipped_frames)
        self._last_late_event_t, self._late_since_event, self._worst_overrun = t, 0, 0.0

    def run(self, until: float | None = None, frames: int | None = None) -> int:
        """Run frames until the clock reads `until` (s), `frames` frames were run, or `stop()`; returns the count."""
        n = 0
        try:
            while not self._stop.is_set():
                if frames is not None and n >= frames:
                    break
                if until is not None and (self._next_t if self._next_t is not None else self.clock.now()) >= until:
                    break
                self.step()
                n += 1
        finally:
            self._stop.clear()
            self._run_pending()
            self._report_unanswered(self.clock.now())  # a run shorter than LINK_STARTUP_S with the dome dark
            self._report_locomotion(self.clock.now(), now=True)  # the log's last word is the state at the end
            self._report_late(self.clock.now(), now=True)  # late frames held back are told before the run ends
        return n

    def stop(self) -> None:
        """Make the running (or the next) `run` return after the current frame (thread-safe)."""
        self._stop.set()

    def start_thread(self, name: str = "frame-loop") -> threading.Thread:
        """Run the loop in a thread of its own until `stop()`."""
        self._loop_thread = threading.Thread(target=self.run, name=name, daemon=True)
        self._loop_thread.start()
        return self._loop_thread

    def join(self, timeout: float | None = None) -> None:
        if self._loop_thread is not None:
            self._loop_thread.join(timeout)

    @property
    def last_frame(self):
        """The LED frame (20350, 2) uint16 most recently rendered (and sent), or None before the first."""
        return self._frame_buf

    # -- statistics ------------------------------------------------------------------------------------
    def stats(self) -> dict[str, Any]:
        """Frame rate, late frames and latency/stage percentiles (s) over the last frames (JSON-serialisable)."""
        n = min(self.frame, STATS_WINDOW)
        window = self._stats[:n] if self.frame <= STATS_WINDOW else self._stats
        out: dict[str, Any] = {"frames": self.frame, "late_frames": self.late_frames,
                               "skipped_frames": self.skipped_frames, "target_rate_hz": self.rate_hz,
                               "frame_rate_hz": None, "locomotion_connected": self.locomotion_connected,
                               "link_ok": self.link_ok, "link_outages": self.link_outages,
                               "rejected_frames": self.rejected_frames, "faults": dict(self.faults),
                               "gpu_busy_passes": self.gpu_busy_passes}
        if n >= 2:
            t = window[:, 0]
            span = float(np.nanmax(t) - np.nanmin(t))
            out["frame_rate_hz"] = (n - 1) / span if span > 0 else None
        for col, name in enumerate(("latency", "render", "sample", "convert", "encode", "send", "pacing_error"),
                                   start=1):
            values = window[:, col]
            values = values[np.isfinite(values)]
            if len(values):
                p50, p99 = np.percentile(values, [50, 99])
                out[name] = {"p50": float(p50), "p99": float(p99), "max": float(values.max())}
            else:
                out[name] = None
        return out
