"""Compiled eye stages (numba): the panoramas of a scan and their Sobel edges in one pass, equal to the numpy
stages of `antarium.ant.eye` (same float32 operations in the same order, no fastmath).

Compiled on first use and cached on disk; single-threaded.
"""

from __future__ import annotations

import numpy as np
from numba import njit

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


def scan_edges(band: np.ndarray, i0: np.ndarray, i1: np.ndarray, w: np.ndarray) -> np.ndarray:
    """`sobel_magnitude` of the panoramas `rotated_panoramas` makes from `band` with the same i0, i1, w:
    (m, rows, cols) float32."""
    out = np.empty((i0.shape[0], band.shape[0], i0.shape[1]), np.float32)
    _scan_edges(np.ascontiguousarray(band, dtype=np.float32), np.ascontiguousarray(i0), np.ascontiguousarray(i1),
                np.ascontiguousarray(w, dtype=np.float32), out)
    return out


@njit(cache=True, nogil=True)
def _sample(indptr, indices, data, x, out):
    """out[i] = float32(sum_j data[j] * x[indices[j]]) over row i of a CSR matrix, summed in float64 in storage
    order (what scipy's product followed by astype(float32) gives)."""
    for i in range(out.shape[0]):
        s = 0.0
        for jj in range(indptr[i], indptr[i + 1]):
            s += data[jj] * np.float64(x[indices[jj]])
        out[i] = np.float32(s)


def sample(matrix, x: np.ndarray) -> np.ndarray:
    """`(matrix @ x).astype(np.float32)` for a float64 CSR `matrix` (n, N) and float32 `x` (N,): (n,) float32."""
    out = np.empty(matrix.shape[0], np.float32)
    _sample(matrix.indptr, matrix.indices, matrix.data, np.ascontiguousarray(x, dtype=np.float32), out)
    return out
