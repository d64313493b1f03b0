"""Compiled per-frame loops (numba): footprint sampling, far-field lookup and 16-bit conversion.

Each LED's values are "pairs": [green, blue] for a GB pixel, [UV, polarised UV] for a UV pixel, so every
loop touches only the two channels that pixel needs. Compiled once per machine (cached next to this file
or in NUMBA_CACHE_DIR); no allocation inside.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

FULL = 65535.0


@njit(parallel=True, cache=True, fastmath=True)
def sample_pairs(indptr, indices, weights, texels, channel, out):  # pragma: no cover - compiled
    """out[i] = sum_k weights[k] * texels[indices[k], channel[i] : channel[i] + 2] over row i of a CSR matrix.

    indptr (n+1,), indices (nnz,) int32; weights (nnz,) float32; texels (T, 4) uint16; channel (n,) int64
    (0 for GB pixels, 2 for UV pixels); out (n, 2) float32.
    """
    for i in prange(len(indptr) - 1):
        c = channel[i]
        a0 = np.float32(0.0)
        a1 = np.float32(0.0)
        for k in range(indptr[i], indptr[i + 1]):
            t = indices[k]
            w = weights[k]
            a0 += w * np.float32(texels[t, c])
            a1 += w * np.float32(texels[t, c + 1])
        out[i, 0] = a0
        out[i, 1] = a1


@njit(cache=True)
def lookup_pairs(table, row, row_frac, col0, shift, out):  # pragma: no cover - compiled
    """Bilinear far-field lookup. table (rows, cols + 1, 2, 2) float32 ([G, B] and [UV, polarised UV] pairs,
    last column = first); row (n,) int64 lower row, row_frac (n,) float32; col0 (n,) float64 column of
    each LED at yaw 0; shift: columns to add; pair index per LED in `pair` column of row (see FarFieldTable).
    out (n, 2) float32."""
    n_cols = table.shape[1] - 1
    for i in range(len(row)):
        c = col0[i] + shift
        ci = np.floor(c)
        f = np.float32(c - ci)
        j = np.int64(ci) % n_cols
        r = row[i] >> 1
        p = row[i] & 1
        fr = row_frac[i]
        for k in range(2):
            a = table[r, j, p, k] + f * (table[r, j + 1, p, k] - table[r, j, p, k])
            b = table[r + 1, j, p, k] + f * (table[r + 1, j + 1, p, k] - table[r + 1, j, p, k])
            out[i, k] = a + fr * (b - a)


@njit(cache=True)
def convert_pairs(pairs, gain, is_uv, swap, out):  # pragma: no cover - compiled
    """Pair radiances (n, 2) float32 in [0, 1] -> LED drives (n, 2) uint16.

    gain (n, 2) float32: 65535 * per-LED gain * brightness * channel gain of each output column.
    GB pixel: (G, B) (swapped if `swap`) * gain, both scaled down together if their sum exceeds 65535.
    UV pixel: plain = (UV - polarised) * gain, polarised * gain, polarised clipped to [0, UV].
    Values are truncated, so every pair's sum stays <= 65535.
    """
    for i in range(len(pairs)):
        p0 = max(pairs[i, 0], np.float32(0.0))
        p1 = max(pairs[i, 1], np.float32(0.0))
        if is_uv[i]:
            total = min(p0 * gain[i, 0], FULL)
            pol = min(p1 * gain[i, 1], total)
            out[i, 0] = np.uint16(total - pol)
            out[i, 1] = np.uint16(pol)
        else:
            if swap:
                p0, p1 = p1, p0
            g = p0 * gain[i, 0]
            b = p1 * gain[i, 1]
            s = g + b
            if s > FULL:
                g *= FULL / s
                b *= FULL / s
            out[i, 0] = np.uint16(min(g, FULL))
            out[i, 1] = np.uint16(min(b, FULL - np.floor(min(g, FULL))))
