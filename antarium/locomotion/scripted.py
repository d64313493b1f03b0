"""A scripted walker: ball rotations for a given path, or for constant speed and turning (with seeded meander).

Samples are produced on a fixed grid of `rate_hz` on the injected clock, so a `SimulatedClock` gives the same
samples as real time, only faster. The rotations are those of the Antarium's ball under an ant walking as
scripted (`antarium.core.ball.pole_motion` inverted):

- tether "free_yaw": the ant turns on its pin, the ball only rolls: rotation (ry, rx) encodes the walked
  displacement along the dome's x and y; rz = 0.
- tether "fixed": the ant always faces the dome's +x; it walks forward (-ry) and turns the ball about z (-rz).
"""

from __future__ import annotations

import math
import random
from typing import Any

from antarium.core.ball import BALL_RADIUS_M, check_tether
from antarium.core.clock import Clock, MonotonicClock
from antarium.locomotion import BallSample, LocomotionSource, positive


class ScriptedSource(LocomotionSource):
    """Walk at `speed` (m/s) turning at `turn_rate` (rad/s), or follow `path` [(x, y), ...] (metres, dome frame).

    meander: standard deviation of a random turn rate (rad/s), redrawn every `spurt_s` seconds (seeded).
    spurt_s: ants walk in spurts; with `pause_fraction` > 0 the walker stands still that share of spurts.
    heading_deg: initial walking direction in the dome frame (free_yaw only: a fixed ant faces the dome's +x).
    duration: stop producing samples after it (s; None: no end).
    """

    def __init__(self, speed: float = 0.02, turn_rate: float = 0.0, path: list | None = None,
                 tether: str = "free_yaw", rate_hz: float = 1000.0, heading_deg: float = 0.0,
                 meander: float = 0.0, spurt_s: float = 1.0, pause_fraction: float = 0.0, seed: int = 0,
                 duration: float | None = None, ball_radius: float = BALL_RADIUS_M, clock: Clock | None = None) -> None:
        checks = {"speed": (speed, 0.0, 2.0), "rate_hz": (rate_hz, 1.0, 100000.0), "meander": (meander, 0.0, 100.0),
                  "spurt_s": (spurt_s, 1e-3, 3600.0), "pause_fraction": (pause_fraction, 0.0, 1.0),
                  "ball_radius": (ball_radius, 1e-3, 1.0), "turn_rate": (turn_rate, -100.0, 100.0),
                  "heading_deg": (heading_deg, -3600.0, 3600.0)}
        for name, (value, lo, hi) in checks.items():
            if not isinstance(value, (int, float)) or not lo <= value <= hi:
                raise ValueError(f"scripted source {name} must be a number in [{lo}, {hi}], got {value!r}")
        check_tether(tether, "scripted source tether")
        if tether == "fixed" and heading_deg != 0:
            raise ValueError(f"scripted source heading_deg applies to the free_yaw tether only (a fixed ant always "
                             "faces the dome's +x; set its world heading with [loop] start_heading_deg), got "
                             f"{heading_deg!r}")
        if duration is not None:
            duration = positive(duration, "scripted source duration", "s; leave it out for no end")
        if path is not None:
            try:
                path = [(float(x), float(y)) for x, y in path]
            except (TypeError, ValueError):
                raise ValueError("scripted source path must be a list of (x, y) points in metres") from None
            if len(path) < 2:
                raise ValueError(f"scripted source path needs at least 2 points, got {len(path)}")
            bad = next((i for i, p in enumerate(path) if not all(map(math.isfinite, p))), None)
            if bad is not None:
                raise ValueError(f"scripted source path point #{bad} must be finite (x, y) metres, got {path[bad]}")
        self.speed, self.turn_rate, self.path, self.tether = float(speed), float(turn_rate), path, tether
        self.dt = 1.0 / float(rate_hz)
        self.meander, self.spurt_s, self.pause_fraction = float(meander), float(spurt_s), float(pause_fraction)
        self.radius = float(ball_radius)
        self.duration = duration
        self.clock = clock or MonotonicClock()
        self._rng = random.Random(seed)
        self._heading = math.radians(heading_deg)
        self._t0: float | None = None
        self._k = 0
        self._spurt_end = -1.0
        self._spurt_turn = 0.0
        self._spurt_speed = self.speed
        self._pos = path[0] if path else (0.0, 0.0)
        self._leg = 1

    def start(self) -> None:
        self._t0 = self.clock.now()
        self._k = 0

    def _step(self, t_rel: float) -> tuple[float, float, float]:
        """Displacement (dx, dy, dyaw) of the walker over one sample period ending at `t_rel`."""
        if t_rel >= self._spurt_end:
            self._spurt_end = t_rel + self.spurt_s
            self._spurt_turn = self._rng.gauss(0.0, self.meander) if self.meander else 0.0
            paused = self.pause_fraction and self._rng.random() < self.pause_fraction
            self._spurt_speed = 0.0 if paused else self.speed
        step = self._spurt_speed * self.dt
        if self.path is not None:
            if self._leg >= len(self.path):
                return 0.0, 0.0, 0.0
            tx, ty = self.path[self._leg]
            ex, ey = tx - self._pos[0], ty - self._pos[1]
            dist = math.hypot(ex, ey)
            if dist <= step:
                self._leg += 1
                step = dist
            want = math.atan2(ey, ex) if dist > 0 else self._heading
            dyaw = math.remainder(want - self._heading, math.tau)
        else:
            dyaw = (self.turn_rate + self._spurt_turn) * self.dt
        self._heading += dyaw
        dx, dy = step * math.cos(self._heading), step * math.sin(self._heading)
        self._pos = (self._pos[0] + dx, self._pos[1] + dy)
        return dx, dy, dyaw

    def read(self) -> list[BallSample]:
        if self._t0 is None:
            self.start()
        now = self.clock.now() - self._t0
        if self.duration is not None:
            now = min(now, self.duration)
        samples = []
        while (self._k + 1) * self.dt <= now + 1e-12:
            self._k += 1
            t_rel = self._k * self.dt
            dx, dy, dyaw = self._step(t_rel)
            r = self.radius
            if self.tether == "free_yaw":
                rotation = (dy / r, -dx / r, 0.0)
            else:  # fixed: forward along the ant's (= dome's) +x, turning shows on the ball as -rz
                forward = math.hypot(dx, dy)
                rotation = (0.0, -forward / r, -dyaw)
            samples.append(BallSample(self._t0 + t_rel, self._k, rotation, t_rel, 1.0))
        return samples

    def status(self) -> dict[str, Any]:
        return {"connected": True, "samples": self._k, "tether": self.tether}
