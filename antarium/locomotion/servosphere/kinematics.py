"""Servosphere kinematics: sphere angular velocity <-> rotor speeds (Goulard et al. 2021, Eqs. 2-6, with the
omniwheel contact model in place of Eq. 4).

Rotor i turns its omniwheel about the unit axis a_i = (cos el_i cos az_i, cos el_i sin az_i, sin el_i) (dome
frame, azimuth counter-clockwise from +x, elevation up from the horizontal); A (the paper's RMat, Eq. 3) has the
a_i as columns (the paper's text swaps the names of azimuth and elevation and prints the second azimuth twice:
0/120/240 deg is the rig). omega: the sphere's angular velocity (rad/s, dome axes); M: the wheels' (rad/s).

Contact model. Wheel i (radius R_w, centre (R_s + R_w) n_i from the ball's centre, n_i a unit vector with
a_i . n_i = 0) touches the ball (radius R_s) at R_s n_i. There its rim moves at M_i a_i x (-R_w n_i) =
-R_w M_i t_i with t_i = a_i x n_i, the ball's surface at omega x (R_s n_i). The omniwheel's rollers let the ball
slide freely along a_i, so only the component along t_i is imposed:

    R_s (omega x n_i) . t_i = -R_w M_i,   and (omega x n_i) . (a_i x n_i) = omega . a_i  (as a_i . n_i = 0)

i.e. R_s (omega . a_i) = -R_w M_i, whatever n_i is: each wheel sees only the ball's rotation about its own axis.
Sign: the wheel and the ball counter-rotate like gears; a wheel speed here is counted positive in the sense that
turns the ball positively about a_i (the paper's convention: one wheel alone turns the ball about +a_i), so

    M = (R_s / R_w) A^T omega,        omega = (R_w / R_s) A^-T M        (A^-T = the transpose of Eq. 6's A^-1)

The paper's Eq. 4, omega = A M R_w / R_s (the ball turning at the vector sum of the M_i a_i), is the same matrix
only when A^-T = A, i.e. for mutually orthogonal rotor axes (elevation atan(1/sqrt 2) = 35.26 deg at azimuths
120 deg apart). At the rig's 60 deg elevation a_i . a_j = 0.625: Eq. 4 would have the ball turn about a_1 when
only wheel 1 turns, which asks the locked wheels 2 and 3 to slide along their drive directions; the contact model
gives omega = (0.667, 0, 0.192) rad/s for M = (1, 0, 0) rad/s where Eq. 4 gives (0.25, 0, 0.433).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from antarium.locomotion.servosphere import finite_numbers

#: the paper's rig: rotors at 0/120/240 deg azimuth, 60 deg elevation; 60 mm omniwheels on a 120 mm ball
AZIMUTH_DEG = (0.0, 120.0, 240.0)
ELEVATION_DEG = (60.0, 60.0, 60.0)
WHEEL_RADIUS_M = 0.030
SPHERE_RADIUS_M = 0.060


def rotor_matrix(azimuth_deg, elevation_deg) -> np.ndarray:
    """RMat (Eq. 3): (3, 3) float64 whose column i is rotor i's unit axis; angles in degrees, 3 each."""
    az = np.radians(np.asarray(azimuth_deg, dtype=np.float64))
    el = np.radians(np.asarray(elevation_deg, dtype=np.float64))
    if az.shape != (3,) or el.shape != (3,):
        raise ValueError(f"need 3 rotor azimuths and 3 elevations (deg), got {az.shape[0] if az.ndim else 1} "
                         f"and {el.shape[0] if el.ndim else 1}")
    return np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])


def inverse_eq6(m: np.ndarray) -> np.ndarray:
    """RMat^-1 by the paper's cofactor formula (Eq. 6); ValueError for rotor axes that do not span 3-D."""
    (a, d, g), (b, e, h), (c, f, i) = m
    det = a * (e * i - f * h) - d * (b * i - c * h) + g * (b * f - c * e)
    if abs(det) < 1e-9:
        raise ValueError(f"rotor axes are (nearly) coplanar (det {det:.2e}); allowed: axes spanning 3-D, "
                         "e.g. three azimuths 120 deg apart with elevation in (0, 90) deg")
    return np.array([[e * i - f * h, f * g - d * i, d * h - e * g],
                     [c * h - b * i, a * i - c * g, b * g - a * h],
                     [b * f - c * e, c * d - a * f, a * e - b * d]]) / det


@dataclass(frozen=True)
class RotorGeometry:
    """Three rotors under a sphere; angles in degrees, radii in metres."""

    azimuth_deg: tuple[float, float, float] = AZIMUTH_DEG
    elevation_deg: tuple[float, float, float] = ELEVATION_DEG
    wheel_radius: float = WHEEL_RADIUS_M
    sphere_radius: float = SPHERE_RADIUS_M

    def __post_init__(self) -> None:
        for name in ("azimuth_deg", "elevation_deg"):
            angles = getattr(self, name)
            if not finite_numbers(angles, 3):
                raise ValueError(f"rotor geometry {name} must be 3 finite angles (deg), got {angles!r}")
        for name in ("wheel_radius", "sphere_radius"):
            value = getattr(self, name)
            if not 1e-4 <= value <= 1.0:
                raise ValueError(f"rotor geometry {name} must be in [1e-4, 1] m, got {value!r}")
        _ = self.to_sphere  # refuses coplanar axes now, not in the loop

    @cached_property
    def rmat(self) -> np.ndarray:
        return rotor_matrix(self.azimuth_deg, self.elevation_deg)

    @cached_property
    def to_sphere(self) -> np.ndarray:
        """(3, 3): wheel speeds (rad/s) -> sphere angular velocity (rad/s), the contact model (R_w/R_s) A^-T
        (A^-1 by Eq. 6); equal to the paper's Eq. 4 for orthogonal rotor axes only."""
        return inverse_eq6(self.rmat).T * (self.wheel_radius / self.sphere_radius)

    @cached_property
    def to_motor(self) -> np.ndarray:
        """(3, 3): sphere angular velocity (rad/s) -> wheel speeds (rad/s), the contact model (R_s/R_w) A^T."""
        return self.rmat.T * (self.sphere_radius / self.wheel_radius)

    def motor_speeds(self, omega: np.ndarray) -> np.ndarray:
        """Wheel speeds (3,) rad/s that turn the sphere at `omega` (3,) rad/s."""
        return self.to_motor @ np.asarray(omega, dtype=np.float64)

    def sphere_omega(self, motor: np.ndarray) -> np.ndarray:
        """Sphere angular velocity (3,) rad/s for wheel speeds `motor` (3,) rad/s (or angles -> rotation)."""
        return self.to_sphere @ np.asarray(motor, dtype=np.float64)


@dataclass(frozen=True)
class StepperLimits:
    """Stepper motors: `steps_per_rev` (full steps x microsteps), top rate (steps/s), acceleration (steps/s^2)."""

    steps_per_rev: int = 3200  # 1.8 deg motor at 1/16 microstepping
    max_rate: float = 16000.0  # 5 rev/s
    max_accel: float = 400000.0  # 125 rev/s^2

    def __post_init__(self) -> None:
        checks = {"steps_per_rev": (self.steps_per_rev, 1, 1_000_000), "max_rate": (self.max_rate, 1.0, 1e6),
                  "max_accel": (self.max_accel, 1.0, 1e9)}
        for name, (value, lo, hi) in checks.items():
            if not lo <= value <= hi:
                raise ValueError(f"stepper {name} must be in [{lo}, {hi}], got {value!r}")

    @property
    def rad_per_step(self) -> float:
        return 2.0 * np.pi / self.steps_per_rev

    def limit(self, rate: np.ndarray, previous: np.ndarray, dt: float) -> np.ndarray:
        """Step rates (3,) steps/s clipped to +-max_rate and to max_accel * dt away from `previous`."""
        dv = self.max_accel * dt
        return np.clip(np.clip(rate, previous - dv, previous + dv), -self.max_rate, self.max_rate)
