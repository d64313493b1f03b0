"""Compiled k-WTA familiarity (numba): the MBONs' novelty for many PN vectors at once, without sorting.

`Workspace(pn_index, k, n_pn).novelty(pn, weights)` equals `MBON.novelty(KenyonCells.active(pn))` for every
MBON in `weights`, and `Workspace.active(pn)` is `KenyonCells.active` (the KCs learning depresses): both select
with `_winners`:
  EP = the sum of each KC's PNs, for 64 PN vectors at once (SIMD over the vectors; the PNs summed in ascending
  index order in float32, the order of the sparse product in `KenyonCells.excitation`, so EP is the same),
  the k-th largest EP of each vector from the candidates above a lower bound (a value that k of the maxima of
  blocks of 16 KCs reach, from their histogram: only the blocks reaching it are read), and lambda = undepressed
  active KCs / k.
Ties at the k-th value (equal EP, e.g. quantised or mostly-zero PNs) are broken toward the lower KC index, in
learning as in recall, so a view just learned reads novelty 0.
Compiled on first use and cached on disk; single-threaded (one core per model in a sweep).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from antarium.ant.tables import index_table

_GROUP = 64  # PN vectors whose EPs are summed together (a 61-direction scan is one group)
_BLOCK = 16  # KCs per block: summed together, then written out direction by direction; one maximum each
_BINS = 128  # of the histogram of a vector's block maxima that bounds its k-th largest EP from below


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", boundscheck=False)
def _excitation(pn_g, pn_index, ep_t, block_max):
    """EP of a group of G vectors into `ep_t` (G, n_kc) float32 and the maxima of blocks of `size` consecutive
    KCs into `block_max` (G, ceil(n_kc / size)), from the group's PNs `pn_g` (n_pn, G). A block's EPs are summed
    together over the G vectors (SIMD; fastmath only lets the compiler vectorise, each EP is still summed in
    ascending PN order), then written out vector by vector."""
    n_kc, p = pn_index.shape
    g = _GROUP  # a compile-time constant: the inner loops unroll into SIMD
    size = (n_kc + block_max.shape[1] - 1) // block_max.shape[1]
    tile = np.empty((size, g), np.float32)
    for b in range(block_max.shape[1]):
        c0 = b * size
        n = min(size, n_kc - c0)
        for t in range(n):
            for d in range(g):
                tile[t, d] = 0.0
            for j in range(p):
                i = pn_index[c0 + t, j]
                for d in range(g):
                    tile[t, d] += pn_g[i, d]
        for d in range(g):
            top = tile[0, d]
            for t in range(n):
                v = tile[t, d]
                ep_t[d, c0 + t] = v
                top = max(top, v)
            block_max[d, b] = top


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _excitation_one(pn, pn_index, ep, block_max):
    """`_excitation` for one PN vector `pn` (n_pn,): EP into ep (1, n_kc), block maxima into block_max (1, n_blocks);
    each EP summed in the same ascending PN order, so it equals the group's."""
    n_kc, p = pn_index.shape
    size = (n_kc + block_max.shape[1] - 1) // block_max.shape[1]
    for b in range(block_max.shape[1]):
        top = -np.inf
        for c in range(b * size, min(n_kc, (b + 1) * size)):
            v = np.float32(0.0)
            for j in range(p):
                v += pn[pn_index[c, j]]
            ep[0, c] = v
            top = max(top, v)
        block_max[0, b] = top


@njit(cache=True, nogil=True)
def _novelty_one(pn, pn_index, k, ep, block_max, weights, out):
    """novelty (1, n_out) into `out` for one PN vector (n_pn,) float32."""
    _excitation_one(pn, pn_index, ep, block_max)
    _select(ep, k, block_max, weights, out)


@njit(cache=True, nogil=True)
def _novelty(pn_groups, pn_index, k, ep_t, block_max, weights, out):
    """novelty (m, n_out) into `out` for PN vectors in groups (n_groups, n_pn, G) (the last one zero-padded),
    with the work arrays ep_t (G, n_kc) and block_max (G, n_blocks) float32."""
    n_groups, _, g = pn_groups.shape
    m = out.shape[0]
    for q in range(n_groups):
        _excitation(pn_groups[q], pn_index, ep_t, block_max)
        d0 = q * g
        _select(ep_t, k, block_max, weights, out[d0:min(m, d0 + g)])


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _kth_largest(a, n, k):
    """The k-th largest of a[:n] (1 <= k <= n), found in place (quickselect; a[:n] is reordered)."""
    lo, hi, target = 0, n - 1, k - 1
    while lo < hi:
        pivot = a[(lo + hi) // 2]
        i, j = lo, hi
        while i <= j:
            while a[i] > pivot:
                i += 1
            while a[j] < pivot:
                j -= 1
            if i <= j:
                a[i], a[j] = a[j], a[i]
                i += 1
                j -= 1
        if target <= j:
            hi = j
        elif target >= i:
            lo = i
        else:
            break
    return a[target]


@njit(cache=True, nogil=True, inline="always")
def _bin(v, lo, scale, bins):
    """The histogram bin of value `v`: bins of width 1 / scale from `lo`, the last one closed."""
    return min(bins - 1, int((v - np.float64(lo)) * scale))


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _lower_bound(values, k, counts):
    """A value that at least k of `values` (k <= len) reach, close below their k-th largest: the smallest of those
    in the histogram bins (len(counts) of them, from their minimum to their maximum) from the one holding the k-th
    largest up. Three passes, no sorting."""
    n = values.shape[0]
    lo = hi = values[0]
    for i in range(n):
        lo = min(lo, values[i])
        hi = max(hi, values[i])
    if not hi > lo:
        return lo
    bins = counts.shape[0]
    scale = bins / (np.float64(hi) - np.float64(lo))
    counts[:] = 0
    for i in range(n):
        counts[_bin(values[i], lo, scale, bins)] += 1
    first, total = 0, 0
    for b in range(bins - 1, -1, -1):
        total += counts[b]
        if total >= k:
            first = b
            break
    low = hi
    for i in range(n):
        if _bin(values[i], lo, scale, bins) >= first:
            low = min(low, values[i])
    return low


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _winners(ep, k, block_max, size, cand, vals, scratch, counts, chosen):
    """The k-WTA of one vector: the indices of its k largest EPs `ep` (n_kc,) float32 into chosen[:k] int32, in
    ascending KC index, ties at the k-th value broken toward the lower KC index; returns how many were written
    (k for finite EPs). The one selection both learning (`active`) and recall (`_select`) use.

    A value that k block maxima reach is a lower bound of the k-th largest EP (k blocks hold a value at least that
    large), so only the blocks whose maximum (`block_max`, blocks of `size` KCs) reaches it can hold active KCs."""
    n_kc = ep.shape[0]
    low = _lower_bound(block_max, k, counts)
    n = 0
    for b in range(block_max.shape[0]):
        if block_max[b] >= low:
            for c in range(b * size, min(n_kc, (b + 1) * size)):
                v = ep[c]
                cand[n] = c  # written always, kept only when it reaches the bound (no branch to mispredict)
                vals[n] = v
                n += v >= low
    scratch[:n] = vals[:n]
    kth = _kth_largest(scratch, n, k)
    ties_left = k
    for i in range(n):
        if vals[i] > kth:
            ties_left -= 1
    j = 0
    for i in range(n):
        v = vals[i]
        take = v > kth
        if not take and v == kth and ties_left > 0:
            take = True
            ties_left -= 1
        if take and j < k:
            chosen[j] = cand[i]
            j += 1
    return j


@njit(cache=True, nogil=True)
def _winner_work(n_kc, k):
    """`_winners`' work arrays for `n_kc` KCs and k winners: cand, vals, scratch, counts, chosen."""
    return (np.empty(n_kc, np.int32), np.empty(n_kc, np.float32), np.empty(n_kc, np.float32),
            np.empty(_BINS, np.int64), np.empty(k, np.int32))


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _select(ep_t, k, block_max, weights, out):
    """novelty (G, n_out) float64 into `out` from EP (G, n_kc) and the MBONs' weights (n_out, n_kc) uint8: the
    undepressed share of each vector's active KCs (`_winners`)."""
    n_kc = ep_t.shape[1]
    size = (n_kc + block_max.shape[1] - 1) // block_max.shape[1]
    n_out = weights.shape[0]
    cand, vals, scratch, counts, chosen = _winner_work(n_kc, k)
    for d in range(out.shape[0]):
        j = _winners(ep_t[d], k, block_max[d], size, cand, vals, scratch, counts, chosen)
        for o in range(n_out):
            total = 0.0
            for i in range(j):
                total += weights[o, chosen[i]]
            out[d, o] = total / k


@njit(cache=True, nogil=True, error_model="numpy", boundscheck=False)
def _pick(ep_t, k, block_max, out):
    """The active KCs (G, k) int64 into `out` of the vectors' EPs (G, n_kc) (`_winners`); -1 fills a row that had
    fewer than k winners (EPs not finite)."""
    n_kc = ep_t.shape[1]
    size = (n_kc + block_max.shape[1] - 1) // block_max.shape[1]
    cand, vals, scratch, counts, chosen = _winner_work(n_kc, k)
    for d in range(out.shape[0]):
        j = _winners(ep_t[d], k, block_max[d], size, cand, vals, scratch, counts, chosen)
        for i in range(k):
            out[d, i] = chosen[i] if i < j else -1


@njit(cache=True, nogil=True)
def _active_one(pn, pn_index, k, ep, block_max, out):
    """The active KCs (1, k) into `out` for one PN vector (n_pn,) float32."""
    _excitation_one(pn, pn_index, ep, block_max)
    _pick(ep, k, block_max, out)


@njit(cache=True, nogil=True)
def _active(pn_groups, pn_index, k, ep_t, block_max, out):
    """The active KCs (m, k) into `out` for PN vectors in groups (n_groups, n_pn, G) (`_novelty`'s layout)."""
    n_groups, _, g = pn_groups.shape
    m = out.shape[0]
    for q in range(n_groups):
        _excitation(pn_groups[q], pn_index, ep_t, block_max)
        d0 = q * g
        _pick(ep_t, k, block_max, out[d0:min(m, d0 + g)])


def sorted_pn_index(pn_index: np.ndarray, n_pn: int) -> np.ndarray:
    """Each KC's PN indices (n_kc, pn_per_kc) in ascending order, C-contiguous int16 (int32 beyond 32,767 PNs):
    the kernel's table."""
    return index_table(np.sort(pn_index, axis=1), n_pn)


class Workspace:
    """The kernel's work arrays for one KC layer, allocated once (fresh multi-MB arrays cost page faults)."""

    def __init__(self, pn_index: np.ndarray, k: int, n_pn: int) -> None:
        self.pn_index = sorted_pn_index(pn_index, n_pn)
        self.k = k
        n_kc = self.pn_index.shape[0]
        block = max(1, min(_BLOCK, n_kc // k))  # at least k blocks
        self.ep_t = np.empty((_GROUP, n_kc), np.float32)
        self.block_max = np.empty((_GROUP, (n_kc + block - 1) // block), np.float32)
        self.groups = np.zeros((1, n_pn, _GROUP), np.float32)

    def _groups(self, pn: np.ndarray) -> np.ndarray:
        """The PN vectors (m, n_pn) in groups (n_groups, n_pn, G), the last one zero-padded."""
        m = pn.shape[0]
        n_groups = -(-m // _GROUP)
        if self.groups.shape[0] < n_groups:
            self.groups = np.zeros((n_groups, self.groups.shape[1], _GROUP), np.float32)
        groups = self.groups[:n_groups]
        for q in range(n_groups):
            part = pn[q * _GROUP:(q + 1) * _GROUP]
            groups[q, :, :part.shape[0]] = part.T
            groups[q, :, part.shape[0]:] = 0.0
        return groups

    def novelty(self, pn: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """lambda (m, n_out) float64 in [0, 1] (1 = novel) of n_out MBONs for PN vectors (m, n_pn) float32;
        weights: (n_out, n_kc) bool or uint8, True = undepressed synapse."""
        m = pn.shape[0]
        out = np.empty((m, weights.shape[0]), np.float64)
        weights = np.ascontiguousarray(weights)
        weights = weights.view(np.uint8) if weights.dtype == np.bool_ else np.ascontiguousarray(weights, np.uint8)
        if m == 1:  # one view (a CXMB decision): no group of 64 to fill
            _novelty_one(np.ascontiguousarray(pn[0], np.float32), self.pn_index, self.k, self.ep_t[:1],
                         self.block_max[:1], weights, out)
            return out
        _novelty(self._groups(pn), self.pn_index, self.k, self.ep_t, self.block_max, weights, out)
        return out

    def active(self, pn: np.ndarray) -> np.ndarray:
        """The active KCs (m, k) int64 (ascending KC index) for PN vectors (m, n_pn) float32: the k largest EPs,
        ties broken toward the lower KC index, the KCs `novelty` reads (so a view just learned reads 0)."""
        m = pn.shape[0]
        out = np.empty((m, self.k), np.int64)
        if m == 1:
            _active_one(np.ascontiguousarray(pn[0], np.float32), self.pn_index, self.k, self.ep_t[:1],
                        self.block_max[:1], out)
        elif m > 1:
            _active(self._groups(pn), self.pn_index, self.k, self.ep_t, self.block_max, out)
        if out.size and out.min() < 0:
            raise ValueError("k-WTA found fewer than k active KCs: the PN input must be finite")
        return out
