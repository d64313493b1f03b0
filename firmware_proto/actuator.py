"""Polariser actuators: aircore rotors driven by sin/cos coil currents, damped second-order settling.

The panel FPGA points the stator field at the target rotor angle; the rotor (a magnet with oil damping) follows as
a damped oscillator, natural frequency OMEGA_RAD_S and damping ratio ZETA, solved in closed form (exact for any
time step). A polariser at theta and theta + pi passes the same e-vector, so the rotor target is whichever of the
two is nearer (at most a 90 deg turn). Coils carry the moving current (54 mA) for HOLD_DELAY_S after a command,
then ramp over HOLD_RAMP_S to the holding current, one quarter of it.
"""

from __future__ import annotations

import numpy as np

OMEGA_RAD_S = 60.0
ZETA = 0.8
MOVING_CURRENT_A = 0.054
HOLDING_CURRENT_A = MOVING_CURRENT_A / 4
HOLD_DELAY_S = 0.3
HOLD_RAMP_S = 0.2
COIL_VOLTAGE_V = 12.0


def _wrap_pi(a):
    """Angle difference wrapped to [-pi, pi)."""
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


class AircoreBank:
    """A bank of aircore actuators of any shape (the emulator uses (55, 9)); times in seconds, angles in rad."""

    def __init__(self, shape: tuple[int, ...], t0: float = 0.0) -> None:
        self.target = np.zeros(shape)   # rotor target angle (unwrapped)
        self.error0 = np.zeros(shape)   # rotor angle - target at t_cmd
        self.rate0 = np.zeros(shape)    # rotor angular velocity at t_cmd
        self.t_cmd = np.full(shape, float(t0) - HOLD_DELAY_S - HOLD_RAMP_S)  # at rest, on holding current

    def _state(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(error, rate) of every rotor at time t: the closed-form underdamped response since its command."""
        dt = np.maximum(t - self.t_cmd, 0.0)
        wd = OMEGA_RAD_S * np.sqrt(1 - ZETA**2)
        decay = np.exp(-ZETA * OMEGA_RAD_S * dt)
        c, s = np.cos(wd * dt), np.sin(wd * dt)
        k = (self.rate0 + ZETA * OMEGA_RAD_S * self.error0) / wd
        err = decay * (self.error0 * c + k * s)
        rate = -ZETA * OMEGA_RAD_S * err + decay * wd * (k * c - self.error0 * s)
        return err, rate

    def rotor_angle(self, t: float) -> np.ndarray:
        """Present rotor angle of every actuator (rad, unwrapped)."""
        return self.target + self._state(t)[0]

    def polariser_angle(self, t: float) -> np.ndarray:
        """Present e-vector angle of every polariser, rad in [0, pi)."""
        a = np.mod(self.rotor_angle(t), np.pi)
        return np.where(a < np.pi, a, 0.0)  # np.mod may round a tiny negative angle up to pi

    def command_rotor(self, t: float, rotor_target, mask=None) -> None:
        """Point the field of the actuators in `mask` (all if None) at `rotor_target` (rad) at time t."""
        err, rate = self._state(t)
        m = np.ones(self.target.shape, bool) if mask is None else np.asarray(mask, bool)
        new_target = np.broadcast_to(np.asarray(rotor_target, np.float64), self.target.shape)
        self.error0 = np.where(m, self.target + err - new_target, self.error0)
        self.rate0 = np.where(m, rate, self.rate0)
        self.t_cmd = np.where(m, t, self.t_cmd)
        self.target = np.where(m, new_target, self.target)

    def command_polariser(self, t: float, angles, mask=None) -> None:
        """Turn the polarisers in `mask` to e-vector `angles` (rad), by the nearer of angle and angle + pi."""
        rotor = self.rotor_angle(t)
        target = rotor + _wrap_pi(2 * (np.asarray(angles) - rotor)) / 2
        self.command_rotor(t, target, mask)

    def coil_current_a(self, t: float) -> np.ndarray:
        """Coil current amplitude of every actuator: moving current, ramped down to the holding current."""
        since = np.maximum(t - self.t_cmd, 0.0)
        frac = np.clip((since - HOLD_DELAY_S) / HOLD_RAMP_S, 0.0, 1.0)
        return MOVING_CURRENT_A + frac * (HOLDING_CURRENT_A - MOVING_CURRENT_A)

    def holding(self, t: float) -> np.ndarray:
        """True where an actuator is on holding current."""
        return np.maximum(t - self.t_cmd, 0.0) >= HOLD_DELAY_S + HOLD_RAMP_S

    def supply_current_a(self, t: float) -> np.ndarray:
        """Current each actuator draws from the 12 V supply: |sin coil| + |cos coil| (at most 77 mA moving)."""
        s, c = self.coil_currents_a(t)
        return np.abs(s) + np.abs(c)

    def coil_currents_a(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(sin coil, cos coil) currents in A: amplitude times sin/cos of the field (target) angle."""
        amp = self.coil_current_a(t)
        return amp * np.sin(self.target), amp * np.cos(self.target)
