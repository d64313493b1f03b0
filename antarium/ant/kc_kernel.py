"""Compiled k-WTA familiarity (numba): the MBONs' novelty for many PN vectors at once, without sorting.

`novelty(pn, pn_index, k, weights)` equals `MBON.novelty(KenyonCells.active(pn))` for every MBON in `weights`:
  EP (n_kc, m) = the sum of each KC's PNs for all m vectors at once (SIMD over m; the PNs summed in ascending
  index order in float32, the order of the sparse product in `KenyonCells.excitation`, so EP is the same),
  the k-th largest EP of each vector from the candidates above a lower bound (the smallest of k block maxima:
  each of the k blocks holds one value at least that large), and lambda = undepressed active KCs / k.
Ties at the k-th value (equal EP) are broken toward the lower KC index; `np.argpartition` breaks them in an
unspecified way, so the two agree exactly whenever the k-th largest EP is unique (any natural image).
Compiled on first use and cached on disk; single-threaded (one core per model in a sweep).
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", boundscheck=False)
def _excitation(pn_t, pn_index, k, ep, block_max):
    """EP (n_kc, m) float32 into `ep` and the maxima of k contiguous KC blocks (k, m) into `block_max`.
    (fastmath only lets the compiler vectorise over m; each EP is still summed in ascending PN order.)"""
    n_kc, p = pn_index.shape
    m = pn_t.shape[1]
    acc = np.empty(m, np.float32)
    for b in range(k):
        for d in range(m):
            block_max[b, d] = -np.inf
    for c in range(n_kc):
        for d in range(m):
            acc[d] = 0.0
        for j in range(p):
            i = pn_index[c, j]
            for d in range(m):
                acc[d] += pn_t[i, d]
        b = (c * k) // n_kc
        for d in range(m):
            ep[c, d] = acc[d]
            block_max[b, d] = max(block_max[b, d], acc[d])


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _select(ep, k, block_max, weights, out):
    """novelty (m, n_out) float64 into `out` from EP (n_kc, m) and the MBONs' weights (n_out, n_kc) uint8."""
    n_kc, m = ep.shape
    n_out = weights.shape[0]
    low = np.empty(m, np.float32)
    for d in range(m):
        low[d] = block_max[:, d].min()
    count = np.zeros(m, np.int64)
    cand = np.empty((m, n_kc), np.int32)
    for c in range(n_kc):
        hit = False
        for d in range(m):
            hit |= ep[c, d] >= low[d]
        if hit:
            for d in range(m):
                if ep[c, d] >= low[d]:
                    cand[d, count[d]] = c
                    count[d] += 1
    for d in range(m):
        n = count[d]
        vals = np.empty(n, np.float32)
        for i in range(n):
            vals[i] = ep[cand[d, i], d]
        kth = np.partition(vals, n - k)[n - k]
        ties_left = k
        for i in range(n):
            if vals[i] > kth:
                ties_left -= 1
        for o in range(n_out):
            out[d, o] = 0.0
        for i in range(n):
            v = vals[i]
            take = v > kth
            if not take and v == kth and ties_left > 0:
                take = True
                ties_left -= 1
            if take:
                c = cand[d, i]
                for o in range(n_out):
                    out[d, o] += weights[o, c]
        for o in range(n_out):
            out[d, o] /= k


def sorted_pn_index(pn_index: np.ndarray) -> np.ndarray:
    """Each KC's PN indices (n_kc, pn_per_kc) in ascending order, int32 C-contiguous (the kernel's table)."""
    return np.ascontiguousarray(np.sort(pn_index, axis=1), dtype=np.int32)


def novelty(pn: np.ndarray, pn_index: np.ndarray, k: int, weights: np.ndarray) -> np.ndarray:
    """lambda (m, n_out) float64 in [0, 1] (1 = novel) of n_out MBONs for PN vectors (m, n_pn) float32.

    pn_index: (n_kc, pn_per_kc) int32 ascending rows (`sorted_pn_index`); k: active KCs per vector (k-WTA);
    weights:  (n_out, n_kc) bool or uint8, True = undepressed synapse.
    """
    pn_t = np.ascontiguousarray(np.asarray(pn, dtype=np.float32).T)
    m = pn_t.shape[1]
    n_kc = pn_index.shape[0]
    ep = np.empty((n_kc, m), np.float32)
    block_max = np.empty((k, m), np.float32)
    _excitation(pn_t, pn_index, k, ep, block_max)
    out = np.empty((m, weights.shape[0]), np.float64)
    _select(ep, k, block_max, np.ascontiguousarray(weights, dtype=np.uint8), out)
    return out
