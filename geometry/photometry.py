"""Photometric geometry: how bright each LED appears from the dome centre, and the gain that evens it out.

A flat panel puts its central LEDs nearer the centre (the inradius, 0.476 m) than its corners (up to the
circumradius, 0.516 m), and the centre sees them closer to their optical axis (the panel's inward normal).
The photon flux at the ant from an LED driven at full scale is I(alpha) / d**2, with d the distance and
alpha the emission angle (between the LED axis and the ray to the centre, cos(alpha) = inradius / d).
The LED's relative intensity is modelled as I(alpha) = cos(alpha) ** m with m set by the half-intensity
angle (LTST-C930 / VLMU3100: 2 theta_half = 130 deg, so m = ln 0.5 / ln cos 65 deg = 0.80).

    gain = (d**2 / I(alpha)) / max over the dome of (d**2 / I(alpha))     (0 < gain <= 1)

Multiplying every LED's drive by its gain makes a uniform scene appear uniform to the ant: the farthest,
most oblique LEDs run at full scale and the central LEDs of every panel are darkened (as in the paper).
"""

from __future__ import annotations

import numpy as np

DEFAULT_HALF_INTENSITY_DEG = 65.0


def emission_angle(positions: np.ndarray, inward_normals: np.ndarray) -> np.ndarray:
    """(N,) rad: angle between each LED's axis (N, 3 unit inward normals) and its ray to the centre.

    positions: (N, 3) metres from the dome centre.
    """
    d = np.linalg.norm(positions, axis=1)
    cos_a = -np.einsum("ij,ij->i", positions, inward_normals) / d
    return np.arccos(np.clip(cos_a, -1.0, 1.0))


def relative_intensity(alpha: np.ndarray, half_intensity_deg: float = DEFAULT_HALF_INTENSITY_DEG) -> np.ndarray:
    """(N,) LED intensity at emission angle alpha (rad) relative to on-axis: cos(alpha) ** m."""
    if not 0 < half_intensity_deg < 90:
        raise ValueError(f"half_intensity_deg must be in (0, 90) degrees, got {half_intensity_deg!r}")
    m = np.log(0.5) / np.log(np.cos(np.radians(half_intensity_deg)))
    return np.cos(alpha) ** m


def compensation_gain(
    positions: np.ndarray, inward_normals: np.ndarray, half_intensity_deg: float = DEFAULT_HALF_INTENSITY_DEG
) -> np.ndarray:
    """(N,) float64 in (0, 1]: per-LED gain that equalises the flux at the centre (see module docstring)."""
    d2 = np.einsum("ij,ij->i", positions, positions)
    need = d2 / relative_intensity(emission_angle(positions, inward_normals), half_intensity_deg)
    return need / need.max()
