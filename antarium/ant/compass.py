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
brighter towards the sun), as ants do with their spectral/intensity gradient: the sky pixels' (lit, polarised at
least `min_degree`: objects in the scene are unpolarised) intensity about their mean, summed along their
directions, so pixels that a nearby object hides pull it to no side (summed over every dorsal pixel, a cylinder
1 cm from the ant towards the sun turned it to the anti-sun: headings 180 deg off, with a cue). The heading is
then the ant's body azimuth relative to the solar azimuth (rad, CCW): the sky compass's zero is the sun's
azimuth, the ideal compass's is the world +x.

The degrees of polarisation must fit the e-vectors' sun: single scattering gives p_i = p_max (1 - c_i^2) /
(1 + c_i^2), c_i = d_i . s. The LED intensities (and so the degrees) follow a turned sky at once while the
polariser actuators take ~0.12 s; until then the e-vectors describe the old sun exactly (residual 0) and would
report the old heading as good. The check (`cx_kernels.degree_excess`): with q_i = (1 - c_i^2) / (1 + c_i^2),
p_max is estimated as the median of p_i / q_i over the sky pixels with q_i >= 0.3, and the root mean square of the
excess max(0, p_i - p_max q_i) / p_max over the sky pixels must stay within `max_degree_excess`. Only the excess
counts: light of an object mixed into a pixel at an object's edge lowers its degree, never raises it. Measured
(face 64, fixed tether): settled skies at most 0.0013 (sun elevations -20 to 89.5 deg, two sun azimuths, twelve
headings each; a cylinder 1 to 7 cm from the ant at four bearings: 0.0012); stale e-vectors 0.28 the frame after
a 57 deg turn, 0.019 after a 3 deg turn (45 deg elevation; 0.021 at 5 deg, 0.022 at -10 deg). Hence 0.003: over
the 40 frames after turns of 0.01 to 1 rad the worst heading error read with a cue was 0.57 deg at sun elevations
-20 to 45 deg, but 4.5 deg at 85 deg and 43 deg at 89.5 deg (near the zenith a turn hardly changes the degree
pattern, and the check cannot see the stale e-vectors).

No cue, no heading: a dark or depolarised dorsal sky, e-vectors that no single sun explains, a sun within
`min_sun_zenith_deg` of the zenith (no solar azimuth) or degrees of polarisation that do not fit the e-vectors'
sun give a `CompassReading` with `cue=False` and a NaN heading (`SkyCompass.heading` then raises
`NoSkyCueError`).
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
    min_sun_zenith_deg: float = 0.2   # fitted sun closer than this to the zenith: no solar azimuth
    max_degree_excess: float = 0.003  # degrees of polarisation above the e-vectors' sun's pattern (rms share of
                                      # p_max): more means the polarisers are still turning

    def __post_init__(self) -> None:
        if not -90.0 <= self.min_elevation_deg < 90.0:
            raise ValueError(f"compass min_elevation_deg must be in [-90, 90), got {self.min_elevation_deg!r}")
        if self.min_pixels < 3:
            raise ValueError(f"compass min_pixels must be >= 3, got {self.min_pixels!r}")
        if not 0.0 <= self.min_intensity < math.inf:  # NaN read every sky as dark, a negative one counted unlit pixels
            raise ValueError(f"compass min_intensity must be a finite number >= 0, got {self.min_intensity!r}")
        if not 0.0 < self.min_degree < 1.0 or not 0.0 < self.max_residual <= 1.0:
            raise ValueError("compass min_degree must be in (0, 1) and max_residual in (0, 1]")
        if not 0.0 <= self.min_sun_zenith_deg < 90.0 or not self.max_degree_excess > 0.0:
            raise ValueError(f"compass min_sun_zenith_deg must be in [0, 90) and max_degree_excess > 0, "
                             f"got {self.min_sun_zenith_deg!r} and {self.max_degree_excess!r}")


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
        from antarium.ant.cx_kernels import compass_fit, degree_excess, eigh3

        self._fit, self._excess, self._eigh = compass_fit, degree_excess, eigh3

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
        lit, pol_lit, total_lit, m, gradient = self._fit(
            led_values, self.pixels, self._scale, self._uv_slot, angles, self._px, self._py, self._dirs,
            p.min_intensity, p.min_degree)
        if lit < p.min_pixels:
            return CompassReading(math.nan, False, why=f"dorsal sky dark ({lit} lit UV pixels)")
        degree = pol_lit / total_lit
        if degree < p.min_degree:
            return CompassReading(math.nan, False, degree, why=f"dorsal sky depolarised (degree {degree:.3f})")
        w, v = self._eigh(m)
        residual = float(w[0] / max(w[1], 1e-12))
        if residual > p.max_residual:
            return CompassReading(math.nan, False, degree, residual, why=f"e-vectors fit no sun (residual "
                                                                         f"{residual:.2f})")
        sun = v[:, 0]
        zenith = math.degrees(math.acos(min(1.0, abs(sun[2]))))
        if zenith < p.min_sun_zenith_deg:
            return CompassReading(math.nan, False, degree, residual, why=f"sun at the zenith ({zenith:.2f} deg "
                                                                         f"from it): no solar azimuth")
        if sun[:2] @ gradient[:2] < 0:
            sun = -sun
        solar_azimuth = math.atan2(sun[1], sun[0])
        excess = self._excess(led_values, self.pixels, self._scale, self._dirs, sun, p.min_intensity, p.min_degree)
        if excess > p.max_degree_excess:
            return CompassReading(math.nan, False, degree, residual, why=f"degrees of polarisation do not fit the "
                                                                         f"e-vectors' sun (excess {excess:.4f} > "
                                                                         f"{p.max_degree_excess}: polarisers turning)")
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
