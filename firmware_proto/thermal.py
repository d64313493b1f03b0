"""Per-panel power and a first-order thermal model (one heat capacity and one thermal resistance per panel).

    P = LED_SUPPLY_V * I_led + COIL_VOLTAGE_V * I_coils         (W)
    C dT/dt = P - (T - AMBIENT_C) / R                             (exact exponential step, any dt)

With every LED of a panel at full scale (7.4 A + 47 x 30 mA at 4.2 V, 37 W) and its actuators idle (1.5 W) a panel
settles 46 K above ambient, with a time constant of R * C = 300 s.
"""

from __future__ import annotations

import numpy as np

LED_SUPPLY_V = 4.2
AMBIENT_C = 22.0
THERMAL_RESISTANCE_K_PER_W = 1.2
TIME_CONSTANT_S = 300.0


class PanelThermal:
    """Temperatures (degC) of `n` panels, advanced in closed form between changes of their power."""

    def __init__(self, n: int, t0: float = 0.0, ambient_c: float = AMBIENT_C) -> None:
        self.ambient_c = ambient_c
        self.temperature_c = np.full(n, ambient_c)
        self.power_w = np.zeros(n)
        self.t = float(t0)

    def advance(self, t: float) -> np.ndarray:
        """Temperatures at time `t` (s) under the present power; returns them."""
        dt = t - self.t
        if dt > 0:
            steady = self.ambient_c + THERMAL_RESISTANCE_K_PER_W * self.power_w
            self.temperature_c = steady + (self.temperature_c - steady) * np.exp(-dt / TIME_CONSTANT_S)
            self.t = t
        return self.temperature_c

    def set_power(self, t: float, power_w) -> None:
        """From time `t` on, the panels dissipate `power_w` (W, shape (n,))."""
        self.advance(t)
        self.power_w = np.asarray(power_w, np.float64).copy()
