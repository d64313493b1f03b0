"""Fast path for scenes that are only far field (sky, panorama, synthetic stimuli): no GL per frame.

A far field at infinity looks the same from every eye position, so an LED's value depends only on the yaw
psi between dome and world: v_i = F~(azimuth_i + psi, elevation_i), where F~ is the far field already
integrated over the LED footprint. F~ is tabulated once per scene, in 16 bits, on a 0.25° (elevation,
azimuth) grid: the field is averaged over each grid cell (sub-samples as fine as its detail needs), blurred
along each row by a periodic Gaussian of width sigma/cos(el) (FFT) and along elevation by a Gaussian of
width sigma, the grid continuing over the zenith (rows beyond 90° are the rows below it, turned by 180°).
Per frame: a bilinear lookup per LED (`kernels.lookup_pairs`).
"""

from __future__ import annotations

import math

import numpy as np

from antarium.geometry.constants import GB_PER_PANEL, PIXELS_PER_PANEL

#: grid step (radians) in elevation and azimuth
STEP = math.radians(0.25)


def _grid_directions(el: np.ndarray, az: np.ndarray) -> np.ndarray:
    """(rows * cols, 3) unit vectors of an (elevation, azimuth) grid that continues over the zenith (rows
    above 90° are the rows below it turned by 180°)."""
    flip = el > math.pi / 2
    el_true = np.where(flip, math.pi - el, el)
    az_grid = az[None, :] + np.where(flip, math.pi, 0.0)[:, None]
    ce = np.cos(el_true)[:, None]
    d = np.empty((len(el), len(az), 3))
    d[..., 0] = ce * np.cos(az_grid)
    d[..., 1] = ce * np.sin(az_grid)
    d[..., 2] = np.sin(el_true)[:, None]
    return d.reshape(-1, 3)


class FarFieldTable:
    """F~ on the grid and the per-LED lookup. directions: (20350, 3) dome-frame LED directions; fwhm (rad)."""

    def __init__(self, scene, directions: np.ndarray, fwhm: float, t: float = 0.0):
        from scipy.ndimage import gaussian_filter1d

        sigma = fwhm / math.sqrt(8 * math.log(2))
        el_led = np.arcsin(np.clip(directions[:, 2], -1, 1))
        margin = 4 * sigma + STEP
        el_lo = el_led.min() - margin
        n_rows = int(math.ceil((math.pi / 2 + margin - el_lo) / STEP))
        self.n_cols = n_cols = int(round(2 * math.pi / STEP))
        el = el_lo + np.arange(n_rows) * STEP
        az = np.arange(n_cols) * STEP
        # the field averaged over each grid cell (s x s sub-samples), so detail finer than the grid cannot alias
        sub = scene.supersample(STEP)
        offsets = (np.arange(sub) - (sub - 1) / 2) * (STEP / sub)
        field = np.zeros((n_rows, n_cols, 4))
        for de in offsets:
            for da in offsets:
                field += scene.evaluate_far(_grid_directions(el + de, az + da), t).reshape(n_rows, n_cols, 4)
        field /= sub * sub
        el_true = np.where(el > math.pi / 2, math.pi - el, el)
        freq = np.fft.rfftfreq(n_cols, d=STEP)  # cycles per radian
        sig_az = sigma / np.maximum(np.cos(el_true), 1e-3)
        transfer = np.exp(-2 * (math.pi * freq[None, :] * sig_az[:, None]) ** 2).astype(np.float32)
        field = np.fft.irfft(np.fft.rfft(field, axis=1) * transfer[:, :, None], n=n_cols, axis=1)
        field = gaussian_filter1d(field.astype(np.float32), sigma / STEP, axis=0, mode="nearest", truncate=3.0)
        # 16-bit fixed point (radiance * 65535), green/blue and UV apart: a quarter of the float table's
        # bytes, so the per-frame gathers mostly hit the cache
        table = np.empty((n_rows, n_cols + 1, 4), dtype=np.uint16)
        table[:, :n_cols] = np.rint(np.clip(field, 0.0, 1.0) * 65535.0)
        table[:, n_cols] = table[:, 0]
        self.table_gb = np.ascontiguousarray(table[..., 0:2])
        self.table_uv = np.ascontiguousarray(table[..., 2:4])
        pos = (el_led - el_lo) / STEP
        row = np.clip(np.floor(pos), 0, n_rows - 2).astype(np.int64)
        is_uv = (np.arange(len(directions)) % PIXELS_PER_PANEL) >= GB_PER_PANEL
        self.row = row
        self.row_frac = (pos - row).astype(np.float32)
        self.col0 = np.mod(np.arctan2(directions[:, 1], directions[:, 0]), 2 * math.pi) / STEP
        order = np.lexsort((self.col0, row))  # sweep the table row by row
        self.order_gb = order[~is_uv[order]]
        self.order_uv = order[is_uv[order]]

    def lookup(self, psi: float, out: np.ndarray) -> np.ndarray:
        """(20350, 2) float32 pair radiances ([G, B] or [UV, polarised UV]) for yaw `psi` (rad) into `out`."""
        from .kernels import lookup_pairs

        shift = (psi / STEP) % self.n_cols
        lookup_pairs(self.table_gb, self.order_gb, self.row, self.row_frac, self.col0, shift, out)
        lookup_pairs(self.table_uv, self.order_uv, self.row, self.row_frac, self.col0, shift, out)
        return out
