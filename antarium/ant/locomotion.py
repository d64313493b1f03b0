"""The virtual ant's legs: motor commands become ball rotations, read by the frame loop like a real trackball's.

`AntLocomotion` is the locomotion back-end "ant" (`open_source("ant", clock=..., tether=...)`). The ant calls
`walk(forward, turn)`; the source turns that into the rotation of the Antarium's ball under an ant doing so
(`antarium.ball.pole_motion` inverted) and hands it out on the next `read()`, stamped with the loop's clock:

- tether "free_yaw": the ant turns on its pin (its `yaw` in the dome frame changes, the ball does not turn);
  walking `forward` rolls the ball so that the pole moves by forward * (cos yaw, sin yaw): rx, ry; rz = 0.
- tether "fixed": the ant always faces the dome's +x; walking rolls the ball about y (ry = -forward / R) and
  turning spins it about z (rz = -turn), and the loop turns the scene instead.
"""

from __future__ import annotations

import math
from typing import Any

from antarium.ball import BALL_RADIUS_M
from antarium.clock import Clock, MonotonicClock
from antarium.locomotion import BallSample, LocomotionSource

TETHERS = ("free_yaw", "fixed")


class AntLocomotion(LocomotionSource):
    """Ball rotations from the virtual ant's `walk` commands.

    tether: "free_yaw" or "fixed"; yaw: the ant's initial heading in the dome frame (rad, free_yaw only);
    ball_radius: metres; clock: the loop's clock (samples are stamped with `clock.now()`).
    """

    def __init__(self, tether: str = "free_yaw", yaw: float = 0.0, ball_radius: float = BALL_RADIUS_M,
                 clock: Clock | None = None) -> None:
        if tether not in TETHERS:
            raise ValueError(f"ant tether must be one of {TETHERS}, got {tether!r}")
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
        else:
            rotation = (0.0, -forward / r, -turn)
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
