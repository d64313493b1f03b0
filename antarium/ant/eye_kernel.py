"""Compiled eye stages (numba): the panoramas of a scan and their Sobel edges in one pass, equal to the numpy
stages of `antarium.ant.eye` (same float32 operations in the same order, no fastmath); the band of a view from
the LED intensities (fine sampling, then the Gaussian acceptance as two sparse passes; float32 sums in another
order than a dense product, so equal to it within rounding).

Compiled on first use and cached on disk; single-threaded.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from antarium.ant.tables import index_table

_ONE = np.float32(1.0)
_TWO = np.float32(2.0)


@njit(cache=True, nogil=True)
def _scan_edges(band, i0, i1, w, out):
    """Sobel magnitude (m, rows, cols) float32 into `out` of the panoramas sampled from `band` (rows, n_fine)
    float32 between fine columns i0 and i1 (m, cols) int64 with weights w (m, cols) float32 (`rotated_panoramas`),
    azimuth wrapping around and elevation edges replicated (`sobel_magnitude`)."""
    m, cols = i0.shape
    rows = band.shape[0]
    pano = np.empty((rows, cols), np.float32)
    for a in range(m):
        for r in range(rows):
            for c in range(cols):
                wa = w[a, c]
                pano[r, c] = band[r, i0[a, c]] * (_ONE - wa) + band[r, i1[a, c]] * wa
        for r in range(rows):
            up = max(r - 1, 0)
            dn = min(r + 1, rows - 1)
            for c in range(cols):
                cl = c - 1 if c > 0 else cols - 1
                cr = c + 1 if c < cols - 1 else 0
                right = pano[up, cr] + _TWO * pano[r, cr] + pano[dn, cr]
                left = pano[up, cl] + _TWO * pano[r, cl] + pano[dn, cl]
                below = pano[dn, cl] + _TWO * pano[dn, c] + pano[dn, cr]
                above = pano[up, cl] + _TWO * pano[up, c] + pano[up, cr]
                gx = right - left
                gy = below - above
                out[a, r, c] = np.sqrt(gx * gx + gy * gy)


@njit(cache=True, nogil=True)
def scan_columns(angles, n_fine, per_col, cols):
    """The fine columns i0, i1 (m, cols) int64 and weights w (m, cols) float32 of the panoramas at `angles` (m,)
    float64 (rad, dome frame; CCW): column c samples fine position c * per_col + angle / (tau / n_fine), between
    i0 = its floor (mod n_fine) and i1 = i0 + 1 (mod n_fine), w the fraction."""
    step = 2.0 * np.pi / n_fine
    m = angles.shape[0]
    i0 = np.empty((m, cols), np.int64)
    i1 = np.empty((m, cols), np.int64)
    w = np.empty((m, cols), np.float32)
    for a in range(m):
        shift = angles[a] / step
        for c in range(cols):
            pos = np.float64(c * per_col) + shift
            lo = np.floor(pos)
            w[a, c] = np.float32(pos - lo)
            i = np.int64(lo) % n_fine
            i0[a, c] = i
            i1[a, c] = (i + 1) % n_fine
    return i0, i1, w


@njit(cache=True, nogil=True)
def _scan_edges_at(band, angles, per_col, cols):
    i0, i1, w = scan_columns(angles, band.shape[1], per_col, cols)
    out = np.empty((angles.shape[0], band.shape[0], cols), np.float32)
    _scan_edges(band, i0, i1, w, out)
    return out


def scan_edges(band: np.ndarray, angles: np.ndarray, per_col: int, cols: int) -> np.ndarray:
    """`sobel_magnitude` of the panoramas `View.rotated_panoramas` makes from `band` (rows, n_fine) at `angles`
    (m,) rad (`scan_columns`): (m, rows, cols) float32, in one compiled call."""
    return _scan_edges_at(np.ascontiguousarray(band, dtype=np.float32), np.ascontiguousarray(angles, np.float64),
                          int(per_col), int(cols))


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def channel_intensities(leds, flat, scale):
    """(n,) float32 intensities of the eye's pixels from the flattened (2 N,) uint16 LED frame `leds`: the sum of
    each pixel's channel columns at `flat` (n, c) int64, as float32 (exact: integers below 2^24), times scale (n,)
    float32 -- what `leds[flat].sum(axis=1, dtype=float32) * scale` gives, without its temporaries."""
    n, c = flat.shape
    out = np.empty(n, np.float32)
    for i in range(n):
        v = np.float32(leds[flat[i, 0]])
        for j in range(1, c):
            v += np.float32(leds[flat[i, j]])
        out[i] = v * scale[i]
    return out


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _band(nb_idx, nb_w, x, el_ptr, el_idx, el_w, taps, h, fine, tmp, ext, out):
    """The eye's band (rows, n_fine) float32 into `out` from intensities x (N,) float32, in three passes:
    fine (fine rows * n_fine,) = each fine point's neighbours nb_idx (K, n) int32 weighted by nb_w (K, n) float32
    (neighbour-major: each pass over the fine points is one gather, and each point's sum still runs over its
    neighbours in order); tmp = B_el fine (CSR B_el (rows, fine rows)); out = tmp circularly convolved along
    azimuth with `taps` (at most n_fine of them, offsets -h ..; B_az is circulant: out[r, c] = sum_k taps[k]
    tmp[r, (c + k - h) mod n_fine]). float32 sums."""
    k_nb, n = nb_idx.shape
    for i in range(n):
        fine[i] = nb_w[0, i] * x[nb_idx[0, i]]
    for j in range(1, k_nb):
        for i in range(n):
            fine[i] += nb_w[j, i] * x[nb_idx[j, i]]
    rows, n_fine = out.shape
    for r in range(rows):
        for c in range(n_fine):
            tmp[r, c] = 0.0
        for jj in range(el_ptr[r], el_ptr[r + 1]):
            w = el_w[jj]
            f0 = el_idx[jj] * n_fine
            for c in range(n_fine):
                tmp[r, c] += w * fine[f0 + c]
        for c in range(h):
            ext[c] = tmp[r, n_fine - h + c]
            ext[h + n_fine + c] = tmp[r, c]
        for c in range(n_fine):
            ext[h + c] = tmp[r, c]
            out[r, c] = 0.0
        for k in range(taps.shape[0]):
            g = taps[k]
            for c in range(n_fine):
                out[r, c] += g * ext[c + k]


class Band:
    """The eye's stage from LED intensities to its band, `blur_el @ (sample @ x).reshape(fine) @ blur_az`, compiled,
    with its tables and work arrays made once. sample: CSR (fine rows * n_fine, N), the same number of neighbours
    in every row; blur_el (rows, fine rows), mostly zeros; blur_az (n_fine, n_fine) circulant (a periodic blur on
    a uniform grid)."""

    def __init__(self, sample_matrix, blur_el: np.ndarray, blur_az: np.ndarray) -> None:
        from scipy import sparse

        counts = np.diff(sample_matrix.indptr)
        if counts.size == 0 or np.any(counts != counts[0]):
            raise ValueError("the eye's fine sampling must give every fine point the same number of neighbours")
        self._nb = (index_table(sample_matrix.indices.reshape(-1, counts[0]).T, sample_matrix.shape[1]),
                    np.ascontiguousarray(sample_matrix.data.reshape(-1, counts[0]).T, dtype=np.float32))
        n_fine = blur_az.shape[0]
        column = np.asarray(blur_az[:, 0], np.float32)
        if blur_az.shape != (n_fine, n_fine) or not np.allclose(
                blur_az, np.stack([np.roll(column, c) for c in range(n_fine)], axis=1), rtol=0, atol=1e-7):
            raise ValueError("the eye's azimuth blur must be circulant")
        support = np.flatnonzero(np.roll(column, n_fine // 2))  # taps centred on offset 0
        h = int(max(n_fine // 2 - support.min(), support.max() - n_fine // 2))
        # out[:, c] = sum_j tmp[:, j] column[(j - c) mod n] = sum_k taps[k] tmp[:, (c + k - h) mod n]; a blur as
        # wide as the circle (2h + 1 > n offsets) takes every offset once, not the opposite one twice
        self._h = h
        self._taps = np.ascontiguousarray(column[(np.arange(min(2 * h + 1, n_fine)) - h) % n_fine])
        el = sparse.csr_matrix(blur_el)
        self._el = (el.indptr, el.indices, el.data.astype(np.float32))
        self._fine = np.empty(sample_matrix.shape[0], np.float32)
        self._tmp = np.empty((blur_el.shape[0], n_fine), np.float32)
        self._ext = np.empty(n_fine + 2 * h, np.float32)
        self.shape = (blur_el.shape[0], n_fine)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(rows, n_fine) float32 band (a new array) for intensities x (N,)."""
        out = np.empty(self.shape, np.float32)
        _band(*self._nb, np.ascontiguousarray(x, dtype=np.float32), *self._el, self._taps, self._h, self._fine,
              self._tmp, self._ext, out)
        return out
