"""Compiled per-frame loops (numba): footprint sampling, far-field lookup and 16-bit conversion.

Each LED's values are "pairs": [green, blue] for a GB pixel, [UV, polarised UV] for a UV pixel, so every
loop touches only the two channels that pixel needs. Compiled once per machine (cached next to this file
or in NUMBA_CACHE_DIR); no allocation inside. Each loop is single-threaded (numba's parallel loops competing
with the GL rasteriser (llvmpipe) were measured 6x slower on 2 cores); the far-field lookup and the sampling
release the GIL, so that the renderer can run them on a helper thread beside its own work.
"""

from __future__ import annotations

import numpy as np
from numba import njit

FULL = 65535.0


@njit(cache=True, fastmath=True)
def sample_pairs(indptr, indices, weights, texels, channel, out):  # pragma: no cover - compiled
    """out[i] = sum_k weights[k] * texels[indices[k], channel[i] : channel[i] + 2] over row i of a CSR matrix.

    indptr (n+1,), indices (nnz,) int32; weights (nnz,) float32; texels (T, 4) uint16 (or float32 in the same
    units, from the float atlas of a far field brighter than 1); channel (n,) int64
    (0 for GB pixels, 2 for UV pixels); out (n, 2) float32.
    """
    for i in range(len(indptr) - 1):
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


@njit(cache=True, fastmath=True, nogil=True)
def sample_over_far(indptr, indices, weights, texels, channel, far, out, lo, hi):  # pragma: no cover - compiled
    """Meshes over a far field, for LEDs lo..hi-1: like `sample_pairs`, with texel channel 3 the meshes'
    coverage (0..1) and `far` (n, 2) the far field already integrated over each LED's footprint, seen where
    nothing covers it: out = meshes + (1 - coverage) * far. Meshes carry no polarisation (UV pixels: polarised
    = far share). Runs without the GIL: two threads may each take a range."""
    for i in range(lo, hi):
        c = channel[i]
        a0 = np.float32(0.0)
        a1 = np.float32(0.0)
        cov = np.float32(0.0)
        for k in range(indptr[i], indptr[i + 1]):
            t = indices[k]
            w = weights[k]
            a0 += w * np.float32(texels[t, c])
            a1 += w * np.float32(texels[t, 1])
            cov += w * np.float32(texels[t, 3])
        u = max(np.float32(1.0) - cov, np.float32(0.0))
        out[i, 0] = a0 + u * far[i, 0]
        if c == 0:
            out[i, 1] = a1 + u * far[i, 1]
        else:
            out[i, 1] = u * far[i, 1]


@njit(cache=True, nogil=True)
def lookup_pairs(table, order, row, row_frac, col0, shift, out):  # pragma: no cover - compiled
    """Bilinear lookup in a far-field table for the LEDs in `order` (sorted by row: cache friendly).

    table (rows, cols + 1, 2) uint16: a channel pair * 65535 per grid point, the last column repeating the
    first; row (n,) int64 lower row; row_frac (n,) float32; col0 (n,) float64: column of each LED at yaw 0;
    shift: columns to add (>= 0); out (n, 2) float32 radiance in [0, 1] (only rows in `order` are written).
    """
    n_cols = table.shape[1] - 1
    scale = np.float32(1.0 / 65535.0)
    for i in order:
        c = col0[i] + shift
        ci = np.int64(c)
        f = np.float32(c - ci)
        j = ci % n_cols
        r = row[i]
        fr = row_frac[i]
        for k in range(2):
            a0 = np.float32(table[r, j, k])
            b0 = np.float32(table[r + 1, j, k])
            a = a0 + f * (np.float32(table[r, j + 1, k]) - a0)
            b = b0 + f * (np.float32(table[r + 1, j + 1, k]) - b0)
            out[i, k] = (a + fr * (b - a)) * scale


@njit(cache=True)
def gather_bilinear(texels, taps, weights, out):  # pragma: no cover - compiled
    """out[p] = sum_k weights[p, k] * texels[taps[p, k]] / 65535: texels (T, 4) uint16; taps (P, 4) int32;
    weights (P, 4) float32; out (P, 4) float32."""
    scale = np.float32(1.0 / 65535.0)
    for p in range(taps.shape[0]):
        for c in range(4):
            acc = np.float32(0.0)
            for k in range(4):
                acc += weights[p, k] * np.float32(texels[taps[p, k], c])
            out[p, c] = acc * scale


@njit(cache=True)
def convert_pairs(pairs, gain, is_uv, swap, out):  # pragma: no cover - compiled
    """Pair radiances (n, 2) float32 in [0, 1] -> LED drives (n, 2) uint16.

    gain (n, 2) float32: 65535 * per-LED gain * brightness * channel gain of each output column.
    GB pixel: (G, B) (swapped if `swap`) * gain, both scaled down together if their sum exceeds 65535.
    UV pixel: plain = (UV - polarised) * gain, polarised * gain, polarised clipped to [0, UV]; a UV above 65535
    (a UV channel gain above 1) scales both down together, so the degree of polarisation stays.
    Values are truncated, so every pair's sum stays <= 65535.
    """
    for i in range(pairs.shape[0]):
        p0 = pairs[i, 0]
        p1 = pairs[i, 1]
        if swap and not is_uv[i]:
            p0, p1 = p1, p0
        a = max(p0, 0.0) * gain[i, 0]
        b = max(p1, 0.0) * gain[i, 1]
        if is_uv[i]:
            if a > FULL:
                b *= FULL / a
                a = FULL
            b = min(b, a)
            a = a - b
        else:
            s = a + b
            if s > FULL:
                a *= FULL / s
                b *= FULL / s
        out[i, 0] = np.uint16(a)
        out[i, 1] = np.uint16(b)


def warm_up() -> None:
    """Compile (or load from the cache) every kernel for the argument types the renderer uses, so that the
    first frame is not late."""
    i64, f32 = np.int64, np.float32
    indptr, indices = np.array([0, 1], i64), np.zeros(1, np.int32)
    weights, texels, channel = np.ones(1, f32), np.zeros((1, 4), np.uint16), np.zeros(1, i64)
    pairs = np.zeros((1, 2), f32)
    sample_pairs(indptr, indices, weights, texels, channel, pairs)
    sample_pairs(indptr, indices, weights, texels.astype(f32), channel, pairs)  # the float atlas (a sun above 1)
    sample_over_far(indptr, indices, weights, texels, channel, pairs, pairs.copy(), 0, 1)
    lookup_pairs(np.zeros((2, 2, 2), np.uint16), np.zeros(1, i64), np.zeros(1, i64), np.zeros(1, f32),
                 np.zeros(1), 0.0, pairs)
    convert_pairs(pairs, pairs.copy(), np.zeros(1, np.bool_), False, np.zeros((1, 2), np.uint16))
