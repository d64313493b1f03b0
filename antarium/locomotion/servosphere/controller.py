"""The servosphere's controller: two PD controllers on the ant's offset from the apex give the ball's angular
velocity (Goulard et al. 2021, Eq. 1, Fig. 2); the kinematics (omniwheel contact model) give the rotor speeds;
the steppers' limits clip them.

Units are ours: the error in mm, kp in (rad/s)/mm, kd in (rad/s)/(mm/s) (the paper's 1.25 and 0.005 act on pixels
of its camera; on mm they give a loop gain kp * R_sphere = 75 /s, a 13 ms time constant, stable at 700 frames/s
with a few ms of latency). The surface at the apex moves at (omega_y R, -omega_x R), so it brings the ant back
with omega_x = +PD(e_y), omega_y = -PD(e_x). omega_z is 0, or with `counter_rotate` turns the ant back to
`yaw_ref_deg` (the ball's yaw then is the ant's turning: run the dome's loop with tether "fixed").
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from antarium.locomotion.servosphere.kinematics import RotorGeometry, StepperLimits


@dataclass
class ControllerConfig:
    kp: float = 1.25
    kd: float = 0.005
    counter_rotate: bool = False
    kp_yaw: float = 20.0  # (rad/s)/rad, only with counter_rotate: a turn of 2 rad/s is held to 0.1 rad
    yaw_ref_deg: float = 0.0
    geometry: RotorGeometry = field(default_factory=RotorGeometry)
    limits: StepperLimits = field(default_factory=StepperLimits)

    def __post_init__(self) -> None:
        for name, hi in (("kp", 100.0), ("kd", 10.0), ("kp_yaw", 1000.0)):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not 0.0 <= value <= hi:
                raise ValueError(f"servosphere controller {name} must be a number in [0, {hi}], got {value!r}")


class Controller:
    """`update(error_mm, heading, dt)` -> step rates (3,) steps/s for the rotors; `None` error (no valid ant)
    ramps the ball to a stop. `omega` holds the desired ball angular velocity (rad/s), `rates` the last rates."""

    def __init__(self, config: ControllerConfig | None = None) -> None:
        self.config = config or ControllerConfig()
        self._steps_per_rad = 1.0 / self.config.limits.rad_per_step
        self._prev: tuple[float, float] | None = None
        self.omega = np.zeros(3)
        self.rates = np.zeros(3)

    def update(self, error_mm: tuple[float, float] | None, heading: float, dt: float) -> np.ndarray:
        cfg = self.config
        if error_mm is None:
            self._prev = None
            self.omega = np.zeros(3)
        else:
            ex, ey = error_mm
            dex, dey = ((ex - self._prev[0]) / dt, (ey - self._prev[1]) / dt) if self._prev and dt > 0 else (0, 0)
            self._prev = (ex, ey)
            wz = 0.0
            if cfg.counter_rotate and math.isfinite(heading):
                wz = -cfg.kp_yaw * math.remainder(heading - math.radians(cfg.yaw_ref_deg), math.tau)
            self.omega = np.array([cfg.kp * ey + cfg.kd * dey, -(cfg.kp * ex + cfg.kd * dex), wz])
        wanted = cfg.geometry.motor_speeds(self.omega) * self._steps_per_rad
        self.rates = cfg.limits.limit(wanted, self.rates, dt)
        return self.rates
