"""A panoramic ant eye reading the dome's LEDs, and Antcar's preprocessing (blur, ~7 deg panorama, Sobel).

The eye sits at the dome centre. It samples the LED intensities on a fine equirectangular grid (nearest LEDs,
Gaussian-weighted), applies the ommatidial Gaussian acceptance as a blur of standard deviation `sigma_deg`
(Antcar: sigma = 3 camera pixels, about 4.4 deg), keeps the `rows` elevations of the low-resolution eye and the
fine azimuth grid (a `View`), and from it makes low-resolution panoramas at any in-silico rotation about the
vertical: `cols` azimuths x `rows` elevations (default 50 x 16 = 800 projection neurons at 7.2 x 7 deg), edge
filtered with a Sobel operator (gradient magnitude; wraps around in azimuth).

Angles: azimuth counter-clockwise from the dome's +x seen from above, elevation up from the horizon (radians).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

#: LED colour channel -> (use UV pixels?, columns of the (N, 2) LED frame summed)
CHANNELS = {"green": (False, (0,)), "blue": (False, (1,)), "uv": (True, (0, 1))}
_FULL_SCALE = 65535.0


@dataclass(frozen=True, slots=True)
class EyeParams:
    """Layout of the eye (degrees only here, at the edge)."""

    channel: str = "green"
    cols: int = 50                 # azimuth samples of the low-resolution panorama (360/50 = 7.2 deg)
    rows: int = 16                 # elevation samples
    elevation_min_deg: float = -35.0
    elevation_max_deg: float = 70.0  # rows spaced (max - min) / (rows - 1) = 7 deg
    sigma_deg: float = 4.4         # Gaussian acceptance (standard deviation)
    fine_per_col: int = 6          # fine azimuth samples per low-resolution column (1.2 deg)
    fine_elevation_deg: float = 1.0
    neighbours: int = 4            # LEDs averaged into each fine sample
    gamma: float = 1.0             # photoreceptor compression: response = intensity ** gamma (1 = linear)
    row_gain: bool = False         # divide each elevation row of the Sobel image by its mean over azimuth

    def __post_init__(self) -> None:
        if self.channel not in CHANNELS:
            raise ValueError(f"eye channel {self.channel!r} not known; allowed: {', '.join(CHANNELS)}")
        for name in ("cols", "rows", "fine_per_col", "neighbours"):
            if int(getattr(self, name)) < 1:
                raise ValueError(f"eye {name} must be >= 1, got {getattr(self, name)!r}")
        if not (-90.0 <= self.elevation_min_deg < self.elevation_max_deg <= 90.0):
            raise ValueError("eye elevations must satisfy -90 <= elevation_min_deg < elevation_max_deg <= 90")
        if not 0 < self.gamma <= 1:
            raise ValueError(f"eye gamma must be in (0, 1] (1 = linear response), got {self.gamma!r}")
        if self.sigma_deg <= 0 or self.fine_elevation_deg <= 0:
            raise ValueError("eye sigma_deg and fine_elevation_deg must be > 0")

    @property
    def n_pn(self) -> int:
        return self.rows * self.cols


class View:
    """What the eye saw once: a (rows, cols * fine_per_col) float32 band in the dome frame and the ant's yaw.

    `pns(angles)` gives the Sobel-filtered low-resolution panoramas (len(angles), rows * cols) float32 as the
    eye would see them if the ant had turned by each angle (radians, counter-clockwise) from where it looked.
    """

    __slots__ = ("band", "yaw", "_per_col", "_cols", "_row_gain")

    def __init__(self, band: np.ndarray, per_col: int, cols: int, yaw: float = 0.0, row_gain: bool = False) -> None:
        self.band = band        # dome-frame band: column 0 faces the dome's azimuth 0
        self.yaw = float(yaw)   # azimuth (rad, dome frame) the ant faced when it looked
        self._per_col = per_col
        self._cols = cols
        self._row_gain = bool(row_gain)

    def _columns(self, angles) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The fine columns i0, i1 (m, cols) int64 and weights w (m, cols) float32 of the panoramas at `angles`."""
        from antarium.ant.eye_kernel import scan_columns

        # Turning CCW by a moves world features to smaller ant-relative azimuths: new(alpha) = old(alpha + a).
        return scan_columns(self._angles(angles), self.band.shape[1], self._per_col, self._cols)

    def _angles(self, angles) -> np.ndarray:
        """(m,) float64 dome-frame azimuths of the turns `angles` (rad, relative to the yaw the view was taken at)."""
        return np.atleast_1d(np.asarray(angles, dtype=np.float64)) + self.yaw

    def rotated_panoramas(self, angles) -> np.ndarray:
        """Low-resolution panoramas (len(angles), rows, cols) float32 after turning by `angles` (rad)."""
        i0, i1, w = self._columns(angles)
        band = self.band
        return band[:, i0].transpose(1, 0, 2) * (1.0 - w[:, None, :]) + band[:, i1].transpose(1, 0, 2) * w[:, None, :]

    def pns(self, angles=(0.0,)) -> np.ndarray:
        """Projection-neuron vectors (len(angles), rows * cols) float32: Sobel magnitude of the panoramas
        (divided row by row by its mean over azimuth when the eye has `row_gain`)."""
        from antarium.ant.eye_kernel import scan_edges  # = sobel_magnitude(self.rotated_panoramas(angles))

        edges = scan_edges(self.band, self._angles(angles), self._per_col, self._cols)
        if self._row_gain:
            edges = row_gain_control(edges)
        return edges.reshape(edges.shape[0], -1)


def sobel_magnitude(pano: np.ndarray) -> np.ndarray:
    """Sobel gradient magnitude of panoramas (..., rows, cols): azimuth wraps around, elevation edges replicate."""
    p = np.concatenate([pano[..., :1, :], pano, pano[..., -1:, :]], axis=-2)
    p = np.concatenate([p[..., -1:], p, p[..., :1]], axis=-1)
    smooth_r = p[..., :-2, :] + 2.0 * p[..., 1:-1, :] + p[..., 2:, :]   # (rows, cols + 2)
    smooth_c = p[..., :, :-2] + 2.0 * p[..., :, 1:-1] + p[..., :, 2:]   # (rows + 2, cols)
    gx = smooth_r[..., :, 2:] - smooth_r[..., :, :-2]
    gy = smooth_c[..., 2:, :] - smooth_c[..., :-2, :]
    return np.sqrt(gx * gx + gy * gy).astype(np.float32)


def row_gain_control(edges: np.ndarray, floor: float = 0.01) -> np.ndarray:
    """Edge images (..., rows, cols) divided row by row by the row's mean over azimuth (plus `floor` times the
    image's mean, so that an empty row stays near 0). Rotation about the vertical commutes with it.

    A gain control per elevation: without it the bright sky around the sun and the horizon, the same wherever
    the ant stands, win the KCs' k-WTA over the nearby grass and stones seen below and just above the horizon.
    """
    row_mean = edges.mean(axis=-1, keepdims=True)
    return (edges / (row_mean + floor * row_mean.mean(axis=-2, keepdims=True) + 1e-12)).astype(np.float32)


def _gaussian_rows(centres: np.ndarray, grid: np.ndarray, sigma: float, periodic: bool) -> np.ndarray:
    """Row-normalised Gaussian weights (len(centres), len(grid)) of grid points around each centre (radians)."""
    delta = grid[None, :] - centres[:, None]
    if periodic:
        delta = np.remainder(delta + math.pi, math.tau) - math.pi
    w = np.exp(-0.5 * (delta / sigma) ** 2)
    w[w < 1e-4] = 0.0
    # A centre farther than ~4.3 sigma from every grid point (a grid coarse against sigma) keeps its nearest point.
    empty = np.flatnonzero(w.sum(axis=1) == 0.0)
    w[empty, np.argmin(np.abs(delta[empty]), axis=1)] = 1.0
    return w / w.sum(axis=1, keepdims=True)


def _nearest_weights(dist: np.ndarray, width: float) -> np.ndarray:
    """Row-normalised Gaussian weights exp(-(dist / width)^2 / 2) (n, K) of each row's K distances (radians),
    computed relative to the row's nearest distance so that a point far from every LED (below the lowest ring)
    still weighs its nearest LEDs instead of underflowing to 0 / 0."""
    w = np.exp(-0.5 * (dist * dist - dist.min(axis=1, keepdims=True) ** 2) / (width * width))
    return w / w.sum(axis=1, keepdims=True)


class Eye:
    """The ant's eye for a given LED layout.

    directions: (N, 3) float64 unit vectors from the dome centre to every LED pixel (dome frame);
    is_uv:      (N,) bool, True for UV pixels (the channel picks GB or UV pixels);
    gain:       (N,) float64 in (0, 1], the dome's photometric compensation gain (`Dome.gain`): an LED driven at
                d appears at the centre as bright as d / gain on the farthest LED, which is what the eye reads.
    """

    def __init__(self, directions: np.ndarray, is_uv: np.ndarray | None = None, params: EyeParams | None = None,
                 gain: np.ndarray | None = None):
        self.params = p = params or EyeParams()
        directions = np.asarray(directions, dtype=np.float64)
        if directions.ndim != 2 or directions.shape[1] != 3:
            raise ValueError(f"LED directions must have shape (N, 3), got {directions.shape}")
        n = directions.shape[0]
        is_uv = np.zeros(n, bool) if is_uv is None else np.asarray(is_uv, dtype=bool)
        if is_uv.shape != (n,):
            raise ValueError(f"is_uv must have shape ({n},), got {is_uv.shape}")
        use_uv, self._columns = CHANNELS[p.channel]
        self._pixels = np.flatnonzero(is_uv == use_uv)
        self._flat = self._pixels[:, None] * 2 + np.asarray(self._columns)[None, :]  # in the flattened (N, 2) frame
        if self._pixels.size < p.neighbours:
            raise ValueError(f"the layout has only {self._pixels.size} {p.channel} pixels")
        self.n_leds = n
        gain = np.ones(n) if gain is None else np.asarray(gain, dtype=np.float64)
        if gain.shape != (n,) or not np.all((gain > 0) & (gain <= 1)):
            raise ValueError(f"gain must be ({n},) floats in (0, 1], got shape {gain.shape}")
        self._scale = (1.0 / (_FULL_SCALE * gain[self._pixels])).astype(np.float32)
        d = directions[self._pixels]
        d = d / np.linalg.norm(d, axis=1, keepdims=True)

        sigma = math.radians(p.sigma_deg)
        n_fine = p.cols * p.fine_per_col
        az = np.arange(n_fine) * (math.tau / n_fine)
        self.elevations = np.radians(np.linspace(p.elevation_min_deg, p.elevation_max_deg, p.rows))
        margin = 3.0 * sigma
        lo = max(-math.pi / 2, self.elevations[0] - margin)
        hi = min(math.pi / 2, self.elevations[-1] + margin)
        fine_el = np.arange(lo, hi + 1e-12, math.radians(p.fine_elevation_deg))

        # Stage 1 (sparse): LED intensities -> fine grid, Gaussian-weighted mean of the nearest LEDs.
        ee, aa = np.meshgrid(fine_el, az, indexing="ij")
        grid = np.stack([np.cos(ee) * np.cos(aa), np.cos(ee) * np.sin(aa), np.sin(ee)], axis=-1).reshape(-1, 3)
        dist, idx = cKDTree(d).query(grid, k=p.neighbours)
        dist = dist.reshape(len(grid), -1)
        idx = idx.reshape(len(grid), -1)
        spacing = float(np.median(dist[:, 0])) + 1e-9
        w = _nearest_weights(dist, max(spacing, 0.5 * math.radians(p.fine_elevation_deg)))
        rows = np.repeat(np.arange(len(grid)), idx.shape[1])
        self._sample = sparse.csr_matrix((w.ravel(), (rows, idx.ravel())), shape=(len(grid), d.shape[0]))
        self._fine_shape = (len(fine_el), n_fine)
        # Stage 2 (dense): Gaussian acceptance, in elevation (selecting the eye's rows) and in azimuth (circular).
        self._blur_el = _gaussian_rows(self.elevations, fine_el, sigma, periodic=False).astype(np.float32)
        self._blur_az = _gaussian_rows(az, az, sigma, periodic=True).T.astype(np.float32)
        for name, table in (("fine sampling", self._sample.data), ("elevation blur", self._blur_el),
                            ("azimuth blur", self._blur_az)):
            if not np.all(np.isfinite(table)):
                raise ValueError(f"the eye's {name} weights are not finite (sigma_deg {p.sigma_deg}, "
                                 f"fine_elevation_deg {p.fine_elevation_deg}); they must be finite numbers")
        self._band = None  # the compiled stages 1-2 (`eye_kernel.Band`), made on first look

    @classmethod
    def from_dome(cls, dome, params: EyeParams | None = None) -> Eye:
        """The eye at the centre of an `antarium.geometry.Dome` (directions, UV pixels, photometric gain)."""
        return cls(dome.directions, dome.is_uv, params, dome.gain)

    def intensities(self, led_values: np.ndarray) -> np.ndarray:
        """Intensities (float32) of the eye's channel from an (N, 2) uint16 LED frame, 1 = farthest LED at full."""
        led_values = np.asarray(led_values)
        if led_values.shape != (self.n_leds, 2):
            raise ValueError(f"LED values must have shape ({self.n_leds}, 2), got {led_values.shape}")
        from antarium.ant.eye_kernel import channel_intensities  # = reshape(-1)[flat].sum(1, float32) * scale

        vals = channel_intensities(led_values.reshape(-1), self._flat, self._scale)
        return vals if self.params.gamma == 1.0 else np.power(vals, np.float32(self.params.gamma))

    def look(self, led_values: np.ndarray, yaw: float = 0.0) -> View:
        """The view of an ant at the dome centre facing azimuth `yaw` (rad, dome frame) from an LED frame."""
        return self.look_intensities(self.intensities(led_values), yaw)

    def look_intensities(self, intensity: np.ndarray, yaw: float = 0.0) -> View:
        """Like `look`, from the channel's intensities ((n_channel_pixels,) floats)."""
        if not math.isfinite(yaw):
            raise ValueError(f"yaw must be a finite angle in radians, got {yaw!r}")
        if self._band is None:
            from antarium.ant.eye_kernel import Band

            self._band = Band(self._sample, self._blur_el, self._blur_az)
        band = self._band(intensity)  # = blur_el @ (sample @ intensity).reshape(fine shape) @ blur_az
        return View(band, self.params.fine_per_col, self.params.cols, yaw, self.params.row_gain)

    @property
    def channel_pixels(self) -> np.ndarray:
        """Global indices (int64) of the LED pixels this eye reads."""
        return self._pixels
