"""A clear sky with a sun: radiance per channel, and single-scattering Rayleigh polarisation (pure numpy).

Radiance follows the CIE standard clear sky (relative to the zenith), tinted per channel (the sky is
brightest in UV). Polarisation at view direction d with the sun at s (gamma = angle between them):

    degree = dop_max * sin^2(gamma) / (1 + cos^2(gamma)),   e-vector along s x d

i.e. perpendicular to the plane through sun, eye and view direction. Below the horizon the sky shows
`ground` (unpolarised).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from antarium.core.numbers import check_number

from .channels import parse_colour

#: Largest sun radiance (1 = full LED drive; above 1 the sun's disc lights the LEDs around it more).
MAX_SUN_RADIANCE = 1000.0
#: Sub-samples per axis (and at least per sun radius) over a grid cell or texel that the sun's rim crosses
RIM_SAMPLES = 8
#: Most sub-samples per axis over such a cell (a sun under 1/32 of a cell in radius is sampled coarser)
MAX_RIM_SUPERSAMPLE = 256


def sun_direction(azimuth: float, elevation: float) -> np.ndarray:
    """(3,) unit vector towards the sun; azimuth from +x counter-clockwise, elevation, in radians."""
    ce = np.cos(elevation)
    return np.array([ce * np.cos(azimuth), ce * np.sin(azimuth), np.sin(elevation)])


def degree_of_polarisation(d: np.ndarray, sun: np.ndarray, dop_max: float) -> np.ndarray:
    """(N,) Rayleigh degree of linear polarisation for (N, 3) unit view directions."""
    cg = np.clip(d @ sun, -1.0, 1.0)
    return dop_max * (1.0 - cg * cg) / (1.0 + cg * cg)


def e_vector(d: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(N, 3) unit e-vector directions (s x d) for (N, 3) view directions; zero towards/away from the sun."""
    e = np.cross(sun, d)
    n = np.linalg.norm(e, axis=1, keepdims=True)
    return np.divide(e, n, out=np.zeros_like(e), where=n > 1e-12)


def cie_clear_sky(d: np.ndarray, sun: np.ndarray) -> np.ndarray:
    """(N,) CIE standard clear-sky relative luminance (1 at the zenith) for directions above the horizon."""
    cos_z = np.clip(d[:, 2], 1e-3, 1.0)
    cg = np.clip(d @ sun, -1.0, 1.0)
    gamma = np.arccos(cg)

    def f(g):
        return 1.0 + 10.0 * (np.exp(-3.0 * g) - np.exp(-np.pi * 1.5)) + 0.45 * np.cos(g) ** 2

    def phi(cz):
        return 1.0 - np.exp(-0.32 / cz)

    zs = np.pi / 2 - np.arcsin(np.clip(sun[2], -1.0, 1.0))
    return f(gamma) * phi(cos_z) / (f(zs) * phi(1.0))


@dataclass
class Sky:
    """The sky as a far-field layer (opaque). Angles in radians; colours as linear (G, B, UV) radiances."""

    sun_azimuth: float = np.radians(135.0)
    sun_elevation: float = np.radians(40.0)
    dop_max: float = 0.75
    zenith: tuple = (0.18, 0.30, 0.45)
    ground: tuple = (0.06, 0.03, 0.008)
    sun_radiance: float = 1.0
    # The real sun (0.27 deg) at radiance <= 1 would average to ~3 % over an LED's 1.5 deg footprint; drawn at
    # half the LED pitch it lights the LEDs around it to about half their range, a visible compass cue.
    sun_radius: float = np.radians(0.75)
    _sun: np.ndarray = field(init=False, repr=False)
    yaw_rate = 0.0
    time_varying = False

    def __post_init__(self) -> None:
        for name in ("sun_azimuth", "sun_elevation", "dop_max", "sun_radius"):
            setattr(self, name, check_number(f"sky {name}", getattr(self, name)))
        self.sun_radiance = check_number("sky sun_radiance", self.sun_radiance, 0.0, MAX_SUN_RADIANCE)
        if not 0.0 < self.sun_radius < np.pi / 2:
            raise ValueError(f"sun radius must be in (0, 90) degrees, got {float(np.degrees(self.sun_radius)):g}")
        if not 0.0 <= self.dop_max <= 1.0:
            raise ValueError(f"sky dop_max must be in [0, 1], got {self.dop_max!r}")
        if not -np.pi / 2 <= self.sun_elevation <= np.pi / 2:
            raise ValueError("sun elevation must be in [-90, 90] degrees, "
                             f"got {float(np.degrees(self.sun_elevation)):g}")
        self.zenith = tuple(parse_colour(self.zenith, "sky zenith colour"))
        self.ground = tuple(parse_colour(self.ground, "sky ground colour"))
        self._sun = sun_direction(self.sun_azimuth, self.sun_elevation)

    def supersample(self, step: float) -> int:
        """Sub-samples per axis to average over a cell of `step` (rad): one, the sky being smooth but for the sun's
        rim, whose cells are averaged apart (`rim_cells`, `rim_supersample`, `Scene.rim_samples`)."""
        return 1

    def rim_cells(self, centres: np.ndarray, step: float) -> np.ndarray:
        """(N,) bool: the cells that the sun's rim may cross, of (N, 3) unit `centres` and at most `step` (rad)
        wide (every point of such a cell lies within step / sqrt(2) of its centre: the test takes `step`)."""
        angle = np.arccos(np.clip(np.asarray(centres) @ self._sun, -1.0, 1.0))
        return np.abs(angle - self.sun_radius) <= step

    def rim_supersample(self, step: float) -> int:
        """Sub-samples per axis that average a cell of `step` (rad) crossed by the sun's rim: RIM_SAMPLES (8) per
        axis, and at least RIM_SAMPLES per sun radius (a sun smaller than a cell), at most MAX_RIM_SUPERSAMPLE.
        A disc sampled once per cell is over- or under-counted by up to a cell's area, tens of percent of an LED's
        value for a sun about a cell wide; at 8 samples per radius its area comes out within about 1 %."""
        return int(min(MAX_RIM_SUPERSAMPLE, max(RIM_SAMPLES, math.ceil(RIM_SAMPLES * step / self.sun_radius))))

    @property
    def sun(self) -> np.ndarray:
        return self._sun

    def evaluate(self, d: np.ndarray, t: float = 0.0) -> np.ndarray:
        """(N, 5) float32 [G, B, UV, polarised UV, alpha=1] for (N, 3) world directions."""
        out = np.empty((len(d), 5), dtype=np.float32)
        above = d[:, 2] > 0.0
        lum = cie_clear_sky(d, self._sun)
        sky = np.clip(lum[:, None] * np.asarray(self.zenith)[None, :], 0.0, 1.0)
        in_sun = (d @ self._sun) >= np.cos(self.sun_radius)
        sky[in_sun] = self.sun_radiance
        out[:, :3] = np.where(above[:, None], sky, np.asarray(self.ground)[None, :])
        out[:, 3] = np.where(above, out[:, 2] * degree_of_polarisation(d, self._sun, self.dop_max), 0.0)
        out[:, 4] = 1.0
        return out
