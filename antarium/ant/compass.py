"""The ant's sky compass, read from the dome: the dorsal rim's UV pixels, their polarised share and the
polarisers' e-vector angles that the emulated panels show (Stone et al. 2017's TB1 input; POL neurons as in
Gkanias et al. 2019), and an ideal compass for comparison.

Each UV pixel of the dome has a plain LED and one behind a polariser turned by an actuator. A dorsal-rim ommatidium
looking at UV pixel i (elevation >= `min_elevation_deg`) sees total UV I_i = plain + polarised (the dome's
photometric gain divided out), degree of polarisation p_i = polarised / I_i and the e-vector e_i that the polariser
angle a_i (rad, in the panel plane from the panel's +x) gives after projection onto the plane normal to the pixel
direction d_i (inverse of `renderers.output.polariser_angles`).

POL neurons: under single scattering every e-vector is normal to the sun, e_i . s = 0, so the population's
solar-meridian estimate is the least-squares sun direction, the smallest eigenvector of sum_i P_i e_i e_i^T
(P_i = polarised intensity). The sign (sun or anti-sun) is taken from the sky's brightness gradient (the sky is
brighter towards the sun), as ants do with their spectral/intensity gradient. The heading is then the ant's
body azimuth relative to the solar azimuth (rad, CCW): the sky compass's zero is the sun's azimuth, the ideal
compass's is the world +x.

No cue, no heading: a dark or depolarised dorsal sky, or e-vectors that no single sun explains, give a
`CompassReading` with `cue=False` and a NaN heading (`SkyCompass.heading` then raises `NoSkyCueError`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_FULL_SCALE = 65535.0


class NoSkyCueError(RuntimeError):
    """The dorsal rim sees no polarised sky the compass can read."""


@dataclass(frozen=True, slots=True)
class CompassReading:
    """heading: rad in (-pi, pi] (NaN without cue); cue: a sky was read; degree: mean degree of polarisation seen;
    residual: smallest / middle eigenvalue of the e-vector fit (0 = a perfect single-scattering sky); why: no cue."""

    heading: float
    cue: bool
    degree: float = math.nan
    residual: float = math.nan
    why: str = ""


@dataclass(frozen=True)
class CompassParams:
    """Which pixels form the dorsal rim and when the sky counts as a cue (degrees only here, at the edge)."""

    min_elevation_deg: float = 30.0   # dorsal rim: UV pixels at least this high (140 of the dome's 495)
    min_intensity: float = 0.01       # a pixel counts as lit above this UV (1 = farthest LED at full)
    min_pixels: int = 12              # lit dorsal pixels needed
    min_degree: float = 0.05          # mean degree of polarisation needed
    max_residual: float = 0.3         # e-vector fit worse than this: no single sun explains them

    def __post_init__(self) -> None:
        if not -90.0 <= self.min_elevation_deg < 90.0:
            raise ValueError(f"compass min_elevation_deg must be in [-90, 90), got {self.min_elevation_deg!r}")
        if self.min_pixels < 3:
            raise ValueError(f"compass min_pixels must be >= 3, got {self.min_pixels!r}")
        if not 0.0 < self.min_degree < 1.0 or not 0.0 < self.max_residual <= 1.0:
            raise ValueError("compass min_degree must be in (0, 1) and max_residual in (0, 1]")


def e_vectors_from_polarisers(directions: np.ndarray, angles: np.ndarray, panel_axes: np.ndarray) -> np.ndarray:
    """(M, 3) unit e-vectors seen along (M, 3) unit pixel `directions` from polariser `angles` (M,) rad in the panel
    plane (from the panel's +x), `panel_axes` (M, 3, 3) rows x, y, normal: the polariser axis projected onto the
    plane normal to the direction (inverse of `renderers.output.polariser_angles`, up to sign)."""
    u = np.cos(angles)[:, None] * panel_axes[:, 0] + np.sin(angles)[:, None] * panel_axes[:, 1]
    e = u - np.einsum("ij,ij->i", u, directions)[:, None] * directions
    return e / np.maximum(np.linalg.norm(e, axis=1, keepdims=True), 1e-12)


class SkyCompass:
    """Heading from the dome's polarised UV pixels (see the module docstring).

    directions (N, 3) LED directions; is_uv (N,) bool; panel (N,) int panel of each pixel; panel_axes (55, 3, 3);
    gain (N,) photometric gain in (0, 1]. The dorsal pixels are taken in global (panel, actuator) order, the
    order of the polarisers' (55, 9) angle array.
    """

    kind = "sky"

    def __init__(self, directions, is_uv, panel, panel_axes, gain=None, params: CompassParams | None = None):
        self.params = p = params or CompassParams()
        directions = np.asarray(directions, np.float64)
        uv = np.flatnonzero(np.asarray(is_uv, bool))
        n_uv = uv.size
        d = directions[uv] / np.linalg.norm(directions[uv], axis=1, keepdims=True)
        dorsal = np.flatnonzero(d[:, 2] >= math.sin(math.radians(p.min_elevation_deg)))
        if dorsal.size < p.min_pixels:
            raise ValueError(f"the layout has only {dorsal.size} UV pixels above {p.min_elevation_deg} deg; "
                             f"the compass needs >= {p.min_pixels}")
        self.n_leds = directions.shape[0]
        self.n_uv = n_uv
        self.pixels = uv[dorsal]                      # global indices of the dorsal-rim pixels
        self._uv_slot = dorsal                        # their places in the (55 * 9) polariser order
        self._dirs = d[dorsal]
        self._axes = np.asarray(panel_axes, np.float64)[np.asarray(panel)[self.pixels]]
        gain = np.ones(self.n_leds) if gain is None else np.asarray(gain, np.float64)
        self._scale = 1.0 / (_FULL_SCALE * gain[self.pixels])
        # the e-vector is linear in the polariser's (cos a, sin a): e ~ cos a px + sin a py, px / py the panel's
        # x / y axes projected normal to the pixel direction (precomputed once; normalised per frame)
        d = self._dirs
        self._px = self._axes[:, 0] - np.einsum("ij,ij->i", self._axes[:, 0], d)[:, None] * d
        self._py = self._axes[:, 1] - np.einsum("ij,ij->i", self._axes[:, 1], d)[:, None] * d
        from antarium.ant.cx_kernels import compass_fit

        self._fit = compass_fit

    @classmethod
    def from_dome(cls, dome, params: CompassParams | None = None) -> SkyCompass:
        return cls(dome.directions, dome.is_uv, dome.panel, dome.panel_axes, dome.gain, params)

    def read(self, led_values: np.ndarray, polariser_angles: np.ndarray, yaw: float = 0.0) -> CompassReading:
        """The compass of an ant facing dome azimuth `yaw` (rad) from the (N, 2) uint16 LEDs the dome shows and the
        polarisers' present (55, 9) angles (rad)."""
        p = self.params
        led_values = np.asarray(led_values)
        if led_values.shape != (self.n_leds, 2):
            raise ValueError(f"LED values must have shape ({self.n_leds}, 2), got {led_values.shape}")
        angles = np.asarray(polariser_angles, np.float64).reshape(-1)
        if angles.size != self.n_uv:
            raise ValueError(f"polariser angles must hold {self.n_uv} values (55 x 9), got {angles.size}")
        lit, pol_lit, total_lit, m, bright = self._fit(led_values, self.pixels, self._scale, self._uv_slot, angles,
                                                       self._px, self._py, self._dirs, p.min_intensity)
        if lit < p.min_pixels:
            return CompassReading(math.nan, False, why=f"dorsal sky dark ({lit} lit UV pixels)")
        degree = pol_lit / total_lit
        if degree < p.min_degree:
            return CompassReading(math.nan, False, degree, why=f"dorsal sky depolarised (degree {degree:.3f})")
        w, v = np.linalg.eigh(m)
        residual = float(w[0] / max(w[1], 1e-12))
        if residual > p.max_residual:
            return CompassReading(math.nan, False, degree, residual, why=f"e-vectors fit no sun (residual "
                                                                         f"{residual:.2f})")
        sun = v[:, 0]
        if sun[:2] @ bright[:2] < 0:
            sun = -sun
        solar_azimuth = math.atan2(sun[1], sun[0])
        return CompassReading(math.remainder(yaw - solar_azimuth, math.tau), True, degree, residual)

    def heading(self, led_values: np.ndarray, polariser_angles: np.ndarray, yaw: float = 0.0) -> float:
        """Like `read`, the heading alone; raises NoSkyCueError when the dorsal rim has no cue."""
        r = self.read(led_values, polariser_angles, yaw)
        if not r.cue:
            raise NoSkyCueError(f"the sky compass has no cue: {r.why}")
        return r.heading


class IdealCompass:
    """The ant's true world heading (rad): the comparison the papers' simulations use."""

    kind = "ideal"

    def read_true(self, heading: float) -> CompassReading:
        return CompassReading(math.remainder(float(heading), math.tau), True, 1.0, 0.0)


COMPASSES = ("sky", "ideal")
