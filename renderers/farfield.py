"""Footprint-integrated far-field tables: an LED's value as a function of the dome's yaw, no GL per frame.

Content seen from a fixed eye position (a far field at infinity, or the far layer of meshes rendered from one
point, `far_layer`) gives every LED a value that depends only on the yaw psi between dome and world:
v_i = F~(azimuth_i + psi, elevation_i), where F~ is the content already integrated over the LED footprint.
F~ is tabulated in 16 bits on a 0.25° (elevation, azimuth) grid (`TableGrid`): the content is averaged over
each grid cell, blurred along each row by a periodic Gaussian of width sigma/cos(el) (FFT) and along
elevation by a Gaussian of width sigma, the grid continuing over the zenith (rows beyond 90° are the rows
below it, turned by 180°). Per frame: a bilinear lookup per LED (`kernels.lookup_pairs`).
"""

from __future__ import annotations

import math

import numpy as np

from antarium.geometry.constants import GB_PER_PANEL, PIXELS_PER_PANEL

#: grid step (radians) in elevation and azimuth
STEP = math.radians(0.25)


def _directions(el: np.ndarray, az: np.ndarray) -> np.ndarray:
    """(..., 3) unit vectors at (elevation, azimuth) arrays (rad, broadcast together) of a grid that continues over
    the zenith: an elevation above 90° is 180° minus it, with the azimuth turned by 180°."""
    el, az = np.asarray(el), np.asarray(az)
    flip = el > math.pi / 2
    el_true = np.where(flip, math.pi - el, el)
    ce = np.where(flip, -1.0, 1.0) * np.cos(el_true)  # the azimuth turned by 180° negates x and y
    x, y = ce * np.cos(az), ce * np.sin(az)
    return np.stack([x, y, np.broadcast_to(np.sin(el_true), x.shape)], axis=-1)


def _grid_directions(el: np.ndarray, az: np.ndarray) -> np.ndarray:
    """(rows * cols, 3) unit vectors of the (elevation, azimuth) grid of rows `el` and columns `az` (`_directions`)."""
    return _directions(el[:, None], az[None, :]).reshape(-1, 3)


class TableGrid:
    """The (elevation, azimuth) grid of the tables for a set of LEDs, and where each LED reads it.

    directions: (20350, 3) dome-frame LED directions; fwhm: footprint width (rad). Rows span the LEDs'
    elevations plus four footprint sigmas, up to 90° and the same margin beyond.
    """

    def __init__(self, directions: np.ndarray, fwhm: float):
        self.fwhm = float(fwhm)
        self.sigma = sigma = fwhm / math.sqrt(8 * math.log(2))
        el_led = np.arcsin(np.clip(directions[:, 2], -1, 1))
        margin = 4 * sigma + STEP
        self.el_lo = el_lo = el_led.min() - margin
        self.n_rows = n_rows = int(math.ceil((math.pi / 2 + margin - el_lo) / STEP))
        self.n_cols = n_cols = int(round(2 * math.pi / STEP))
        self.el = el_lo + np.arange(n_rows) * STEP
        self.az = np.arange(n_cols) * STEP
        pos = (el_led - el_lo) / STEP
        row = np.clip(np.floor(pos), 0, n_rows - 2).astype(np.int64)
        is_uv = (np.arange(len(directions)) % PIXELS_PER_PANEL) >= GB_PER_PANEL
        self.row = row
        self.row_frac = (pos - row).astype(np.float32)
        self.col0 = np.mod(np.arctan2(directions[:, 1], directions[:, 0]), 2 * math.pi) / STEP
        order = np.lexsort((self.col0, row))  # sweep the table row by row
        self.order_gb = order[~is_uv[order]]
        self.order_uv = order[is_uv[order]]
        el_true = np.where(self.el > math.pi / 2, math.pi - self.el, self.el)
        freq = np.fft.rfftfreq(n_cols, d=STEP)  # cycles per radian
        sig_az = sigma / np.maximum(np.cos(el_true), 1e-3)
        self._transfer = np.exp(-2 * (math.pi * freq[None, :] * sig_az[:, None]) ** 2).astype(np.float32)

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols + 1) of a table: the last column repeats the first."""
        return self.n_rows, self.n_cols + 1

    def directions(self, d_el: float = 0.0, d_az: float = 0.0) -> np.ndarray:
        """(rows * cols, 3) world directions of the grid points, offset by (d_el, d_az) radians."""
        return _grid_directions(self.el + d_el, self.az + d_az)

    def blur(self, field: np.ndarray) -> np.ndarray:
        """(rows, cols, C) float32: `field` (content averaged over each cell) blurred by the LED footprint."""
        import scipy.fft
        from scipy.ndimage import gaussian_filter1d

        spectrum = scipy.fft.rfft(np.asarray(field, dtype=np.float32), axis=1, workers=1)
        spectrum *= self._transfer[:, :, None]
        blurred = scipy.fft.irfft(spectrum, n=self.n_cols, axis=1, workers=1)
        return gaussian_filter1d(blurred, self.sigma / STEP, axis=0, mode="nearest", truncate=3.0)

    def spread(self, excess: np.ndarray) -> np.ndarray:
        """(rows, cols, C) float32: `excess` (content above 1, averaged over each cell; zero almost everywhere)
        integrated over the LED footprint truncated at one FWHM, as `footprint.build_matrix` truncates it.

        Content above 1 (a sun brighter than full drive) is spread apart from the rest: the separable blur's
        Gaussian has tails beyond one FWHM, negligible for radiance <= 1 but, times a radiance of up to 1000, they
        would light LEDs that the footprint matrix (the GL path) leaves dark. Sources are the cells at or below the
        zenith (each sky cell once), weights g(angle) * cell solid angle over the footprint's integral.
        """
        from .footprint import gaussian_weight, pairs_within

        out = np.zeros(excess.shape, dtype=np.float32)
        el_true = np.where(self.el > math.pi / 2, math.pi - self.el, self.el)
        rows, cols = np.nonzero(np.any(excess > 0, axis=2) & (self.el <= math.pi / 2)[:, None])
        if len(rows) == 0:
            return out
        radius = self.fwhm
        # targets: grid points whose true elevation is within the footprint of a source row (both sides of the zenith)
        near = (el_true >= el_true[rows].min() - radius - STEP) & (el_true <= el_true[rows].max() + radius + STEP)
        t_rows = np.flatnonzero(near)
        targets = _grid_directions(self.el[t_rows], self.az)
        sources = _grid_directions(self.el[rows], self.az)[np.arange(len(rows)) * self.n_cols + cols]
        t_idx, s_idx, angle = pairs_within(targets, sources, radius)
        area = STEP * (np.sin(el_true[rows] + STEP / 2) - np.sin(el_true[rows] - STEP / 2))  # cell solid angles
        theta = np.linspace(0.0, radius, 2001)
        norm = np.trapezoid(2.0 * math.pi * gaussian_weight(theta, self.fwhm) * np.sin(theta), theta)
        w = gaussian_weight(angle, self.fwhm) * area[s_idx] / norm
        flat = np.zeros((len(targets), excess.shape[2]))
        np.add.at(flat, t_idx, w[:, None] * excess[rows[s_idx], cols[s_idx]])
        out[t_rows] = flat.reshape(len(t_rows), self.n_cols, -1)
        return out

    def quantise(self, values: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Radiance (rows, cols, C) in [0, 1] (clipped) into `out` (rows, cols + 1, C) uint16 as value * 65535,
        the last column repeating the first; returns `out`."""
        v = np.clip(values, 0.0, 1.0) * 65535.0
        np.rint(v, out=out[:, : self.n_cols], casting="unsafe")
        out[:, self.n_cols] = out[:, 0]
        return out


class FarFieldTable:
    """Footprint-integrated content as two tables on `grid`, [G, B] and [UV, polarised UV], each
    (rows, cols + 1, 2) uint16 (radiance * 65535: a quarter of a float table's bytes, so the per-frame gathers
    mostly hit the cache), and the per-LED lookup."""

    def __init__(self, grid: TableGrid, table_gb: np.ndarray, table_uv: np.ndarray):
        self.grid, self.table_gb, self.table_uv = grid, table_gb, table_uv

    @classmethod
    def of_scene(cls, scene, directions: np.ndarray, fwhm: float, t: float = 0.0) -> FarFieldTable:
        """The far field of `scene` at time t (s) for LEDs at (20350, 3) dome-frame `directions`, footprint
        `fwhm` (rad)."""
        g = TableGrid(directions, fwhm)
        # The field averaged over each grid cell (s x s sub-samples, more where a sun's rim crosses it), so detail
        # finer than the grid cannot alias; content up to 1 and above 1 (a sun above full drive, its footprint
        # truncated as the matrix's) averaged apart, so that a cell the sun's rim crosses blurs what it would at
        # radiance 1 and only the part above 1 is spread.
        sub = scene.supersample(STEP)
        offsets = (np.arange(sub) - (sub - 1) / 2) * (STEP / sub)
        centres = g.directions()
        low = np.zeros((g.n_rows, g.n_cols, 4), dtype=np.float32)
        high = np.zeros_like(low)
        for de in offsets:
            for da in offsets:
                v = scene.evaluate_far(centres if sub == 1 else g.directions(de, da), t).reshape(low.shape)
                low += np.minimum(v, 1.0)
                high += np.maximum(v - 1.0, 0.0)
        low /= sub * sub
        high /= sub * sub

        def cell_samples(idx: np.ndarray, n: int) -> np.ndarray:
            r, c = np.divmod(idx, g.n_cols)
            o = (np.arange(n) - (n - 1) / 2) * (STEP / n)
            return _directions(g.el[r, None, None] + o[:, None], g.az[c, None, None] + o)

        idx, v = scene.rim_samples(centres, STEP, cell_samples, t)
        low.reshape(-1, 4)[idx] = np.minimum(v, 1.0).mean(axis=1)
        high.reshape(-1, 4)[idx] = np.maximum(v - 1.0, 0.0).mean(axis=1)
        blurred = g.blur(low) + g.spread(high) if high.max() > 0.0 else g.blur(low)
        table = g.quantise(blurred, np.empty((*g.shape, 4), dtype=np.uint16))
        return cls(g, np.ascontiguousarray(table[..., 0:2]), np.ascontiguousarray(table[..., 2:4]))

    def lookup(self, psi: float, out: np.ndarray) -> np.ndarray:
        """(20350, 2) float32 pair radiances ([G, B] or [UV, polarised UV]) for yaw `psi` (rad) into `out`."""
        from .kernels import lookup_pairs

        g = self.grid
        shift = (psi / STEP) % g.n_cols
        lookup_pairs(self.table_gb, g.order_gb, g.row, g.row_frac, g.col0, shift, out)
        lookup_pairs(self.table_uv, g.order_uv, g.row, g.row_frac, g.col0, shift, out)
        return out
