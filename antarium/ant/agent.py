"""The virtual ant in the closed loop: it reads what the dome shows and walks through a locomotion source.

Per decision: `loop.step()` (the frame loop integrates the ant's last ball rotations into the pose, renders,
encodes and sends the frame through the link), the eye reads the LEDs the dome now shows (the virtual link's
emulated panel buffers), the model decides, and the legs (`AntLocomotion`) turn the command into ball rotations
for the next frame. Nothing here renders, encodes or paces: that is the frame loop's, on the loop's clock.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from antarium.ant.eye import Eye, View
from antarium.ant.locomotion import AntLocomotion, BusLegs, TrackballLegs
from antarium.ant.metrics import ARDIN_ERROR_DISTANCE_M, RunSummary, arrived, stopping_distance
from antarium.ant.routes import Route
from antarium.core.pose import Pose


@dataclass
class Track:
    """Where the ant was at each decision (world frame) and what its model said."""

    t: list[float] = field(default_factory=list)
    xy: list[tuple[float, float]] = field(default_factory=list)
    heading: list[float] = field(default_factory=list)
    traces: list[dict[str, float]] = field(default_factory=list)
    put_back: list[int] = field(default_factory=list)  # decision indices at which the ant was put back

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        return np.asarray(self.xy, np.float64).reshape(-1, 2), np.asarray(self.heading, np.float64)

    def trace(self, key: str) -> np.ndarray:
        return np.array([tr.get(key, math.nan) for tr in self.traces])


class VirtualAnt:
    """An eye, a model and legs in a frame loop.

    loop:      `antarium.server.frame_loop.FrameLoop` whose `source` is `legs` (`legs.source` for `TrackballLegs`; the
               loop's "bus" source for `BusLegs`)
    read_leds: returns the (20350, 2) uint16 LEDs the dome shows now (`link.emulator.led_values`)
    frames_per_decision: frames the loop runs per decision; the command is spread evenly over them
    cue_wait_frames: when the sky compass has no cue (e.g. the polarisers still turning after a turn of the scene
               in the fixed tether), the ant stands still for up to this many frames, reading the compass each
               frame, before its model decides without a cue (and raises NoSkyCueError); 0: it does not wait
    """

    def __init__(self, eye: Eye, model, loop, legs: AntLocomotion | BusLegs | TrackballLegs,
                 read_leds: Callable[[], np.ndarray], frames_per_decision: int = 1,
                 delivery_timeout_s: float = 2.0, compass=None,
                 read_polarisers: Callable[[], np.ndarray] | None = None, cue_wait_frames: int = 0) -> None:
        if isinstance(legs, BusLegs):
            if not hasattr(loop.source, "received"):
                raise ValueError("legs on the bus need a frame loop reading the bus (open_source('bus', ...))")
        elif loop.source is not getattr(legs, "source", legs):
            raise ValueError("the frame loop must read the ant's legs (FrameLoop(source=legs, ...), "
                             "source=legs.source for TrackballLegs)")
        if loop.tether != legs.tether:
            raise ValueError(f"loop tether {loop.tether!r} and ant tether {legs.tether!r} differ")
        if int(frames_per_decision) < 1:
            raise ValueError(f"frames_per_decision must be >= 1, got {frames_per_decision}")
        if int(cue_wait_frames) < 0:
            raise ValueError(f"cue_wait_frames must be >= 0, got {cue_wait_frames}")
        self.cue_wait_frames = int(cue_wait_frames)
        self.cue_waits = 0  # frames stood still waiting for a compass cue, over the ant's life
        self.eye, self.model, self.loop, self.legs, self.read_leds = eye, model, loop, legs, read_leds
        self.frames_per_decision = int(frames_per_decision)
        self.delivery_timeout_s = float(delivery_timeout_s)
        self._queued: tuple[float, float] = (0.0, 0.0)
        self.compass, self.read_polarisers = compass, read_polarisers
        self._sensed_at: tuple[float, float] | None = None

    # -- where the ant is ------------------------------------------------------------------------------
    @property
    def heading(self) -> float:
        """The ant's heading in the world (rad): the dome's azimuth in the world plus its yaw on the pin."""
        return math.remainder(self.loop.pose.heading + self.legs.yaw, math.tau)

    @property
    def position(self) -> tuple[float, float]:
        return self.loop.pose.x, self.loop.pose.y

    def place(self, x: float, y: float, heading: float) -> None:
        """Put the ant at (x, y) m facing `heading` (rad, world), as an experimenter displacing it would."""
        pose = self.loop.pose
        self.legs.read()  # steps not yet taken are dropped
        self._queued = (0.0, 0.0)
        self._sensed_at = (x, y)  # a carried ant feels no walk, and sees no flow
        if hasattr(self.model, "carried"):
            self.model.carried()
        if self.legs.tether == "free_yaw":
            self.loop.set_pose(Pose(x, y, pose.z, pose.heading))
            self.legs.turn_to(heading - pose.heading)
        else:
            self.loop.set_pose(Pose(x, y, pose.z, heading))

    # -- sensing and acting ----------------------------------------------------------------------------
    def frame(self) -> None:
        """Run the loop's frames of one decision, walking the queued command evenly over them."""
        forward, turn = self._queued
        n = self.frames_per_decision
        for _ in range(n):
            if forward or turn:
                self.legs.walk(forward / n, turn / n)
                self._await_delivery()
            self.loop.step()
        self._queued = (0.0, 0.0)

    def _await_delivery(self) -> None:
        """Legs on the bus: wait (bounded, wall time) until the loop's bus source has received every step, so that
        a simulated clock never runs ahead of the messages."""
        if not isinstance(self.legs, BusLegs):
            return
        deadline = time.monotonic() + self.delivery_timeout_s
        while self.loop.source.received < self.legs.published:
            if time.monotonic() > deadline:
                raise RuntimeError(f"the bus did not deliver the ant's steps within {self.delivery_timeout_s} s "
                                   f"({self.loop.source.received} of {self.legs.published} received)")
            time.sleep(0.0002)

    def look(self) -> View:
        return self.eye.look(self.read_leds(), yaw=self.legs.yaw)

    def sense(self):
        """`Senses` for the central-complex models: the view, the compass (the sky compass reads the dome's UV
        pixels and polarisers; the ideal one the true heading) and the distance walked since the last `sense`,
        as the loop integrated it from the ball."""
        from antarium.ant.compass import IdealCompass
        from antarium.ant.navigation import Senses

        if self.compass is None:
            raise ValueError("this ant has no compass (virtual_rig(..., compass='sky' | 'ideal'))")
        leds = self.read_leds()
        yaw = self.legs.yaw
        if isinstance(self.compass, IdealCompass):
            reading = self.compass.read_true(self.heading)
        else:
            reading = self.compass.read(leds, self.read_polarisers(), yaw)
            for _ in range(self.cue_wait_frames if not reading.cue else 0):
                self.loop.step()  # nothing queued: the ant stands still while the dome settles
                self.cue_waits += 1
                leds = self.read_leds()
                reading = self.compass.read(leds, self.read_polarisers(), yaw)
                if reading.cue:
                    break
        x, y = self.position
        last = self._sensed_at or (x, y)
        self._sensed_at = (x, y)
        view = self.eye.look(leds, yaw=yaw) if getattr(self.model, "needs_view", True) else None
        return Senses(view, reading, math.hypot(x - last[0], y - last[1]), leds, yaw)

    def act(self, forward: float, turn: float) -> None:
        """Queue a command: it is walked during the next `frame()`."""
        self._queued = (float(forward), float(turn))

    def decide(self):
        """Show the current pose, look, decide and queue the command; returns the `Command`."""
        self.frame()
        cmd = self.model.decide(self.sense() if getattr(self.model, "uses_senses", False) else self.look())
        self.act(cmd.forward, cmd.turn)
        return cmd


def learning_walk(ant: VirtualAnt, route: Route, spacing: float, place_length: float = 0.1,
                  progress: Callable[[int], None] | None = None, keep: list | None = None,
                  keep_every: int = 10) -> int:
    """Walk the ant along `route`, learning a view every `spacing` metres; returns the number of views.
    Every `keep_every`-th learned `View` is appended to `keep` when given (e.g. for PI_error).

    Facing along the route it learns with its model's rule (Antcar: in-silico oscillation into the left and
    right MBONs). Antcar also learns its nest place MBON on the first and its feeder MBON on the last
    `place_length` metres. The ant is carried: placed at each point (the loop logs every displacement).
    """
    points, headings = route.sample(spacing)
    learns_places = hasattr(ant.model, "learn_place")
    s = np.linspace(0.0, route.length, len(points))
    for i, ((x, y), h) in enumerate(zip(points, headings, strict=True)):
        ant.place(float(x), float(y), float(h))
        ant.frame()
        view = ant.look()
        ant.model.learn(view)
        if keep is not None and i % keep_every == 0:
            keep.append(view)
        if learns_places and s[i] <= place_length:
            ant.model.learn_place(view, "nest")
        if learns_places and s[i] >= route.length - place_length:
            ant.model.learn_place(view, "feeder")
        if progress is not None:
            progress(1)
    return len(points)


@dataclass
class FollowResult:
    track: Track
    summary: RunSummary


def follow_route(ant: VirtualAnt, route: Route, max_decisions: int, arrive_radius: float = 0.1,
                 put_back_distance: float = ARDIN_ERROR_DISTANCE_M, start_offset: tuple[float, float] = (0.0, 0.0),
                 stop_after: int = 5, end_on_arrival: bool = True,
                 progress: Callable[[int], None] | None = None) -> FollowResult:
    """Release the ant at the route's start and let it walk in closed loop.

    start_offset: (lateral metres, left > 0; heading error rad, CCW > 0) at release.
    The run ends on arrival within `arrive_radius` of the end (unless `end_on_arrival` is False, e.g. to see
    a homing ant stop by itself), after `stop_after` decisions without moving (e.g. Antcar stopped at the nest;
    the stopping distance to the route's end is then reported), or after `max_decisions`. Ardin's protocol:
    when the ant is farther than `put_back_distance` from the route, that counts an error and it is put back on
    the nearest route point, facing along the route.
    """
    ant.model.reset()
    (x0, y0), (h0,) = route.at([0.0])[0][0], route.at([0.0])[1]
    lateral, dh = start_offset
    ant.place(x0 - lateral * math.sin(h0), y0 + lateral * math.cos(h0), h0 + dh)
    track = Track()
    errors = 0
    still = 0
    for k in range(max_decisions):
        cmd = ant.decide()
        t = ant.loop.clock.now()
        x, y = ant.position
        track.t.append(t)
        track.xy.append((x, y))
        track.heading.append(ant.heading)
        track.traces.append(cmd.trace)
        ant.loop.event("ant_decision", forward=cmd.forward, turn=cmd.turn, **cmd.trace)
        if progress is not None:
            progress(1)
        if end_on_arrival and arrived(route, [(x, y)], arrive_radius):
            break
        still = still + 1 if cmd.forward == 0.0 else 0
        if still >= stop_after:
            break
        s, d, h = route.project([(x, y)])
        if abs(d[0]) > put_back_distance:
            errors += 1
            (px, py), = route.at(s)[0]
            ant.place(float(px), float(py), float(h[0]))
            track.put_back.append(k)
    xy, heading = track.arrays()
    stop = stopping_distance(route, xy[-1]) if still >= stop_after else math.nan
    summary = RunSummary.of(route, xy, heading, arrived(route, xy, arrive_radius), errors, stop)
    return FollowResult(track, summary)
