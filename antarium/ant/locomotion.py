"""The virtual ant's legs: motor commands become ball rotations, read by the frame loop like a real trackball's.

`AntLocomotion` is the locomotion back-end "ant" (`open_source("ant", clock=..., tether=...)`). The ant calls
`walk(forward, turn)`; the source turns that into the rotation of the Antarium's ball under an ant doing so
(`antarium.core.ball.pole_motion` inverted) and hands it out on the next `read()`, stamped with the loop's clock:

- tether "free_yaw": the ant turns on its pin (its `yaw` in the dome frame changes, the ball does not turn);
  walking `forward` rolls the ball so that the pole moves by forward * (cos yaw, sin yaw): rx, ry; rz = 0.
- tether "fixed": the ant always faces the dome's +x; walking rolls the ball about y (ry = -forward / R) and
  turning spins it about z (rz = -turn), and the loop turns the scene instead.

The same rotations can take the way a real ant's do: `BusLegs` publishes them on the bus (a trackball on another
computer), `TrackballLegs` turns them into the motion of the emulated USB trackball, read by the real driver.
"""

from __future__ import annotations

import math
import threading
import time
from typing import Any

from antarium.core.ball import BALL_RADIUS_M, check_tether, chord_ratio
from antarium.core.clock import Clock, MonotonicClock
from antarium.core.rates import FRAME_PERIOD_S
from antarium.locomotion import BallSample, LocomotionSource


class AntLocomotion(LocomotionSource):
    """Ball rotations from the virtual ant's `walk` commands.

    tether: "free_yaw" or "fixed"; yaw: the ant's initial heading in the dome frame (rad, free_yaw only);
    ball_radius: metres; clock: the loop's clock (samples are stamped with `clock.now()`).
    """

    def __init__(self, tether: str = "free_yaw", yaw: float = 0.0, ball_radius: float = BALL_RADIUS_M,
                 clock: Clock | None = None) -> None:
        check_tether(tether, "ant tether")
        if not isinstance(yaw, (int, float)) or not math.isfinite(yaw):
            raise ValueError(f"ant yaw must be a finite angle in radians, got {yaw!r}")
        if not isinstance(ball_radius, (int, float)) or not 1e-3 <= ball_radius <= 1.0:
            raise ValueError(f"ball_radius must be in [0.001, 1] m, got {ball_radius!r}")
        self.tether = tether
        self.yaw = float(yaw) if tether == "free_yaw" else 0.0
        self.radius = float(ball_radius)
        self.clock = clock or MonotonicClock()
        self._pending: list[BallSample] = []
        self._seq = 0

    def walk(self, forward: float, turn: float) -> BallSample:
        """Turn by `turn` rad (CCW), then walk `forward` metres along the body axis (negative: backward)."""
        if not (math.isfinite(forward) and math.isfinite(turn)):
            raise ValueError(f"ant command must be finite (metres, radians), got forward={forward!r}, turn={turn!r}")
        r = self.radius
        if self.tether == "free_yaw":
            self.yaw = math.remainder(self.yaw + turn, math.tau)
            rotation = (forward * math.sin(self.yaw) / r, -forward * math.cos(self.yaw) / r, 0.0)
        else:  # the loop integrates a step along its arc: this chord is the turn, then the walk
            arc = forward / chord_ratio(turn)
            rotation = (arc * math.sin(0.5 * turn) / r, -arc * math.cos(0.5 * turn) / r, -turn)
        sample = BallSample(self.clock.now(), self._seq, rotation, None, 1.0)
        self._seq += 1
        self._pending.append(sample)
        return sample

    def turn_to(self, yaw: float) -> None:
        """Put the ant's body at dome azimuth `yaw` (rad) on its pin (free_yaw), as an experimenter would."""
        if self.tether != "free_yaw":
            raise ValueError("the ant can be turned on its pin only in the free_yaw tether")
        self.yaw = math.remainder(float(yaw), math.tau)

    def read(self) -> list[BallSample]:
        out, self._pending = self._pending, []
        return out

    def status(self) -> dict[str, Any]:
        return {"connected": True, "samples": self._seq, "tether": self.tether, "yaw": self.yaw}


class BusLegs:
    """The ant's legs on the bus: every step is published as a 44-byte `antarium.locomotion.wire` sample on
    `antarium/<rig>/locomotion`, where the frame loop's "bus" source reads it — as it would read a trackball on
    another computer. Rotations are those of `AntLocomotion` (same tethers); `published` counts the steps.

    session: an open zenoh session (`antarium.bus.open_session`); rig: the rig's name.
    """

    def __init__(self, session, rig: str = "rig1", tether: str = "free_yaw", yaw: float = 0.0,
                 ball_radius: float = BALL_RADIUS_M, clock: Clock | None = None) -> None:
        from antarium.bus import check_rig_name, locomotion_publisher

        self._legs = AntLocomotion(tether, yaw, ball_radius, clock)
        self._publisher = locomotion_publisher(session, check_rig_name(rig))
        self.published = 0

    @property
    def tether(self) -> str:
        return self._legs.tether

    @property
    def yaw(self) -> float:
        return self._legs.yaw

    def walk(self, forward: float, turn: float) -> BallSample:
        """Like `AntLocomotion.walk`, and publish the sample."""
        from antarium.locomotion import wire

        sample = self._legs.walk(forward, turn)
        self._legs.read()
        self._publisher.put(wire.encode(sample))
        self.published += 1
        return sample

    def turn_to(self, yaw: float) -> None:
        self._legs.turn_to(yaw)

    def read(self) -> list[BallSample]:
        """Nothing to read here: the samples travel over the bus."""
        return []

    def close(self) -> None:
        self._publisher.undeclare()


class Strides:
    """The ball's motion under the ant's steps: piecewise-constant rotation over device-time intervals, integrated
    exactly (`rotation(t0, t1)`, the `EmulatedTrackball` motion interface). Thread-safe: steps are added by the ant,
    integrated by the device's reader."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._steps: list[tuple[float, float, tuple[float, float, float]]] = []  # (start, end, rotation rad)

    def add(self, start: float, end: float, rotation: tuple[float, float, float]) -> None:
        with self._lock:
            self._steps.append((start, end, rotation))

    def clear(self) -> None:
        """Stop the ball: steps not yet reported are dropped."""
        with self._lock:
            self._steps.clear()

    def rotation(self, t0: float, t1: float) -> tuple[float, float, float]:
        """Rotation (rad, dome axes) of the ball between device times t0 and t1 (s); steps ended by t0 are
        forgotten (the device reports in order)."""
        out = [0.0, 0.0, 0.0]
        with self._lock:
            self._steps = [s for s in self._steps if s[1] > t0]
            for start, end, rot in self._steps:
                overlap = min(end, t1) - max(start, t0)
                if overlap > 0:
                    f = overlap / (end - start)
                    out[0] += f * rot[0]
                    out[1] += f * rot[1]
                    out[2] += f * rot[2]
        return out[0], out[1], out[2]


class _InStep(LocomotionSource):
    """The frame loop's view of `TrackballLegs`: the driver's samples, after every report the device had ready
    at the clock's present has been handled (so a simulated clock never runs ahead of the device)."""

    def __init__(self, legs: TrackballLegs) -> None:
        self._legs = legs

    def read(self) -> list[BallSample]:
        self._legs.settle()
        return self._legs.driver.read()

    def status(self) -> dict[str, Any]:
        return self._legs.driver.status()


class TrackballLegs:
    """The ant's legs on the emulated USB trackball, read by the real driver (pyusb code path).

    Each step's rotation (as `AntLocomotion` computes it, same tethers) becomes the ball's motion in an
    `EmulatedTrackball` over the next `step_s` seconds of the device's clock — the loop's clock, so that the
    device keeps step with a frame loop on a `SimulatedClock` (faster than real time, reproducible) or runs in
    real time on a `MonotonicClock`. Its 32-byte reports are read, decoded and solved by `UsbTrackball`, whose
    samples the frame loop reads through `source`. With `step_s` one frame period and a report rate that is a
    multiple of the frame rate (950 Hz for 190 frames/s, the default), a step is reported in full by the next
    frame, quantised to the sensors' counts (remainders carried, as a real sensor's).

    trackball: the `[trackball]` section (dict, file or `TrackballConfig`) of the device and the driver;
    on_sample / on_event: the driver's callbacks (e.g. publishing on the bus); settle_timeout_s: wall time
    `source.read()` waits at most for the device's due reports.
    """

    def __init__(self, tether: str = "free_yaw", yaw: float = 0.0, trackball: Any = None,
                 clock: Clock | None = None, step_s: float = FRAME_PERIOD_S, on_sample=None, on_event=None,
                 settle_timeout_s: float = 2.0) -> None:
        from antarium.locomotion.trackball import config as tbconfig
        from antarium.locomotion.trackball.driver import UsbTrackball
        from antarium.locomotion.trackball.emulator import EmulatedTrackball

        config = tbconfig.load(trackball) if trackball is not None else tbconfig.TrackballConfig(sample_rate_hz=950)
        if not (isinstance(step_s, (int, float)) and 0.0 < step_s <= 10.0):
            raise ValueError(f"step_s must be in (0, 10] seconds, got {step_s!r}")
        self.clock = clock or MonotonicClock()
        self._legs = AntLocomotion(tether, yaw, config.ball_radius, self.clock)
        self.strides = Strides()
        self.device = EmulatedTrackball(motion=self.strides, truth=config, clock=self.clock)
        self.driver = UsbTrackball(config, backend=self.device, clock=self.clock, on_sample=on_sample,
                                   on_event=on_event)
        self.source = _InStep(self)
        self.step_s = float(step_s)
        self.settle_timeout_s = float(settle_timeout_s)
        self._end = 0.0  # device time at which the last step ends

    @property
    def tether(self) -> str:
        return self._legs.tether

    @property
    def yaw(self) -> float:
        return self._legs.yaw

    def start(self) -> None:
        """Start the driver and wait (wall time, bounded) until it has started the device."""
        self.driver.start()
        deadline = time.monotonic() + self.settle_timeout_s
        while not (self.driver.status()["connected"] and self.device.running):
            if time.monotonic() > deadline:
                self.driver.stop()
                raise RuntimeError(f"the emulated trackball did not start within {self.settle_timeout_s} s "
                                   f"({self.driver.last_error or 'no error reported'})")
            time.sleep(0.001)
        self._end = self.device.now()

    def stop(self) -> None:
        self.driver.stop()

    def walk(self, forward: float, turn: float) -> BallSample:
        """Like `AntLocomotion.walk`; the ball turns by the step's rotation over the next `step_s` seconds."""
        sample = self._legs.walk(forward, turn)
        self._legs.read()
        start = max(self.device.now(), self._end)
        self._end = start + self.step_s
        self.strides.add(start, self._end, sample.rotation)
        return sample

    def turn_to(self, yaw: float) -> None:
        self._legs.turn_to(yaw)

    def settle(self) -> None:
        """Wait (wall time, bounded) until the driver has handled every report the device has ready now."""
        device, counters = self.device, self.driver.counters
        deadline = time.monotonic() + self.settle_timeout_s
        while True:
            device.wake()
            handled = counters["reports"] + counters["short_reports"] + counters["bad_reports"]
            if not device.due() and handled >= device.transfers:
                return
            if time.monotonic() > deadline:
                raise RuntimeError(f"the trackball driver did not read the emulated device's reports within "
                                   f"{self.settle_timeout_s} s ({handled} of {device.transfers} handled)")
            time.sleep(0.0001)

    def read(self) -> list[BallSample]:
        """Steps not yet taken are dropped (the ant is lifted): the ball stops and the driver's samples are
        discarded. Returns nothing: the frame loop reads the driver."""
        self.strides.clear()
        self.settle()
        self.driver.read()
        self._end = self.device.now()
        return []
