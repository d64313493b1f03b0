"""Mushroom-body building blocks: PN -> KC random expansion with k-winner-take-all, and binary KC -> MBON synapses.

Conventions follow Gattaux et al. 2025 (Antcar), equations 1-7:
  EP = PNtoKC . PN (each KC sums `pn_per_kc` random PNs), AP = the `kappa * n_kc` largest EP (binary),
  learning depresses KC->MBON synapses of active KCs (1 -> 0, anti-Hebbian), and
  lambda = (1 / N_u) sum_i AP_i KCtoMBON_i  -- the fraction of active KCs whose synapse is still undepressed,
  so lambda = 1 for a novel view and 0 for a learned one.
"""

from __future__ import annotations

import numpy as np
from scipy import sparse


def check_wiring(n_kc: int, pn_per_kc: int, kappa: float, n_pn: int | None = None, name: str = "") -> None:
    """ValueError unless n_kc >= 1, pn_per_kc in 1..n_pn (>= 1 when n_pn is None) and 0 < kappa <= 1; `name`
    prefixes n_kc's name in the message (e.g. "place_" for Antcar's place KCs)."""
    if n_pn is None and not pn_per_kc >= 1:
        raise ValueError(f"pn_per_kc must be >= 1, got {pn_per_kc}")
    if n_pn is not None and not 1 <= pn_per_kc <= n_pn:
        raise ValueError(f"pn_per_kc must be in 1..{n_pn}, got {pn_per_kc}")
    if not n_kc >= 1:
        raise ValueError(f"{name}n_kc must be >= 1, got {n_kc}")
    if not 0.0 < kappa <= 1.0:
        raise ValueError(f"kappa must be in (0, 1], got {kappa}")


class KenyonCells:
    """A fixed random PN -> KC expansion.

    n_pn:       number of projection neurons (input length)
    n_kc:       number of Kenyon cells
    pn_per_kc:  distinct PNs feeding each KC (binary synapses)
    kappa:      fraction of KCs active after k-WTA (k = round(kappa * n_kc), at least 1)
    seed:       the connectivity is a pure function of (n_pn, n_kc, pn_per_kc, seed), so files store the seed only
    """

    def __init__(self, n_pn: int, n_kc: int, pn_per_kc: int, kappa: float, seed: int) -> None:
        check_wiring(n_kc, pn_per_kc, kappa, n_pn)
        self.n_pn, self.n_kc, self.pn_per_kc, self.kappa, self.seed = n_pn, n_kc, pn_per_kc, kappa, int(seed)
        self.k = max(1, round(kappa * n_kc))
        rng = np.random.default_rng(self.seed)
        idx = rng.integers(0, n_pn, size=(n_kc, pn_per_kc))
        # Redraw the rows that picked a PN twice until every KC has distinct inputs.
        while True:
            s = np.sort(idx, axis=1)
            bad = np.flatnonzero((s[:, 1:] == s[:, :-1]).any(axis=1))
            if bad.size == 0:
                break
            idx[bad] = rng.integers(0, n_pn, size=(bad.size, pn_per_kc))
        self.pn_index = idx
        self._kernel = None  # the compiled kernel's tables and work arrays, made on first `novelty`
        self._weights = np.empty((0, n_kc), bool)  # the MBONs' synapses as `novelty` hands them to the kernel
        data = np.ones(idx.size, dtype=np.float32)
        # (n_pn, n_kc) so that EP = PN @ matrix for a batch of PN rows.
        self._matrix = sparse.csr_matrix(
            (data, (idx.ravel(), np.repeat(np.arange(n_kc), pn_per_kc))), shape=(n_pn, n_kc)
        )

    def excitation(self, pn: np.ndarray) -> np.ndarray:
        """EP (m, n_kc) float32 for PN vectors (m, n_pn)."""
        pn = np.asarray(pn, dtype=np.float32)
        if pn.ndim != 2 or pn.shape[1] != self.n_pn:
            raise ValueError(f"PN input must have shape (m, {self.n_pn}), got {pn.shape}")
        return np.asarray(self._matrix.T.dot(pn.T).T)

    def _workspace(self, pn: np.ndarray):
        """The compiled kernel's workspace (made on first use) and `pn` as float32 (m, n_pn), its shape checked."""
        from antarium.ant import kc_kernel

        pn = np.asarray(pn, dtype=np.float32)
        if pn.ndim != 2 or pn.shape[1] != self.n_pn:
            raise ValueError(f"PN input must have shape (m, {self.n_pn}), got {pn.shape}")
        if self._kernel is None:
            self._kernel = kc_kernel.Workspace(self.pn_index, self.k, self.n_pn)
        return self._kernel, pn

    def active(self, pn: np.ndarray) -> np.ndarray:
        """Indices (m, k) int64 of the active KCs (k-WTA: the k largest EPs, ties broken toward the lower KC index,
        ascending) for PN vectors (m, n_pn): the same selection `novelty` makes (`kc_kernel._winners`), so a view
        just learned reads novelty 0."""
        kernel, pn = self._workspace(pn)
        return kernel.active(pn)

    def novelty(self, pn: np.ndarray, mbons: list[MBON]) -> np.ndarray:
        """lambda (m, len(mbons)) float64 of each MBON for PN vectors (m, n_pn): `mbon.novelty(self.active(pn))`
        for all of them in one compiled pass without sorting (`kc_kernel`; ties broken toward lower KC index)."""
        kernel, pn = self._workspace(pn)
        if len(self._weights) != len(mbons):
            self._weights = np.empty((len(mbons), self.n_kc), bool)
        for row, mbon in zip(self._weights, mbons, strict=True):  # copied into one (n, n_kc) table the kernel reads
            if mbon.n_kc != self.n_kc:
                raise ValueError(f"an MBON of {mbon.n_kc} KCs cannot read a layer of {self.n_kc} KCs")
            row[:] = mbon.weights
        return kernel.novelty(pn, self._weights)


class MBON:
    """One output neuron with binary KC -> MBON synapses (True = undepressed), all undepressed at first."""

    def __init__(self, n_kc: int, weights: np.ndarray | None = None) -> None:
        if weights is None:
            weights = np.ones(n_kc, dtype=bool)
        weights = np.asarray(weights)
        if weights.shape != (n_kc,) or weights.dtype != bool:
            raise ValueError(f"MBON weights must be a ({n_kc},) bool array, got {weights.shape} {weights.dtype}")
        self.weights = weights.copy()

    @property
    def n_kc(self) -> int:
        return self.weights.shape[0]

    def learn(self, active: np.ndarray) -> None:
        """Depress the synapses of the active KCs (indices, any shape): equation 4."""
        self.weights[np.asarray(active).ravel()] = False

    def novelty(self, active: np.ndarray) -> np.ndarray:
        """lambda (equation 7) for each row of active-KC indices (m, k): float64 in [0, 1], 1 = novel."""
        active = np.atleast_2d(active)
        return self.weights[active].mean(axis=1)

    def packed(self) -> np.ndarray:
        """The synapses bit-packed: (ceil(n_kc / 8),) uint8."""
        return np.packbits(self.weights)

    @classmethod
    def from_packed(cls, packed: np.ndarray, n_kc: int) -> MBON:
        packed = np.asarray(packed)
        expected = (n_kc + 7) // 8
        if packed.dtype != np.uint8 or packed.shape != (expected,):
            raise ValueError(
                f"packed MBON weights for {n_kc} KCs must be ({expected},) uint8, got {packed.shape} {packed.dtype}"
            )
        return cls(n_kc, np.unpackbits(packed, count=n_kc).astype(bool))
