"""Per-LED acceptance footprints: the sparse matrix from cube-map texels to LEDs, and a numpy reference.

Every LED integrates the radiance of the cube map over its angular acceptance: a Gaussian of full width at
half maximum `fwhm` (radians) around its direction, truncated at `radius` (default: one FWHM, where the
weight has fallen to 1/16). The weight of texel t for LED i is

    W[i, t] = g(angle(d_i, t)) * solid_angle(t) / sum_t' g(angle(d_i, t')) * solid_angle(t')

so each row sums to 1 and an LED reports the footprint-weighted mean radiance: texture finer than the LED
pitch averages out instead of aliasing. Matrices are cached on disk per (directions, face size, widths).
"""

from __future__ import annotations

import hashlib
import math
import os
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from .cubemap import atlas_directions, atlas_solid_angles

_CACHE_VERSION = 1

#: The dome's LED pitch (degrees): the default FWHM of an LED's acceptance.
LED_PITCH_DEG = 1.5
#: Widest footprint (FWHM, degrees: the LED acceptance widened by any angular low-pass) a matrix is built for.
#: Every limit on the low-pass (`max_lowpass_deg`) derives from it.
MAX_FWHM_DEG = 45.0


def lowpass_fwhm(cutoff_deg: float) -> float:
    """FWHM (rad) of the Gaussian whose response is 1/2 at spatial period `cutoff_deg`."""
    sigma = math.sqrt(math.log(2.0) / 2.0) / math.pi * math.radians(cutoff_deg)
    return sigma * math.sqrt(8.0 * math.log(2.0))


def footprint_fwhm(footprint_deg: float, lowpass_deg: float | None) -> float:
    """FWHM (rad) of an LED acceptance of `footprint_deg` widened by an angular low-pass of `lowpass_deg` (None:
    none)."""
    fwhm = math.radians(footprint_deg)
    return fwhm if lowpass_deg is None else math.hypot(fwhm, lowpass_fwhm(lowpass_deg))


def max_lowpass_deg(footprint_deg: float = LED_PITCH_DEG) -> float:
    """Largest low-pass cut-off period (degrees, rounded down to 0.1) that keeps an LED acceptance of
    `footprint_deg` widened by it under MAX_FWHM_DEG (101.9 for the 1.5 degree pitch)."""
    per_deg = math.degrees(lowpass_fwhm(1.0))  # low-pass FWHM (degrees) per degree of cut-off period
    return math.floor(10.0 * math.sqrt(MAX_FWHM_DEG ** 2 - footprint_deg ** 2) / per_deg) / 10.0


def min_face_size(footprint_deg: float = LED_PITCH_DEG) -> int:
    """Smallest cube face side (texels) at which every direction has a texel centre within one FWHM
    `footprint_deg` (the footprint's radius), so that every LED sees a texel: the farthest any direction lies from
    its nearest texel centre is atan(sqrt(2) / N), at a face centre between its four middle texels (55 for the
    1.5 degree pitch)."""
    return math.ceil(math.sqrt(2.0) / math.tan(math.radians(footprint_deg)))


def gaussian_weight(angle: np.ndarray, fwhm: float) -> np.ndarray:
    """Acceptance g(angle) = exp(-4 ln 2 angle^2 / fwhm^2); angle and fwhm in radians."""
    return np.exp(-4.0 * np.log(2.0) * (np.asarray(angle) / fwhm) ** 2)


def pairs_within(a: np.ndarray, b: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair of (N, 3) unit vectors `a` and (M, 3) unit vectors `b` at most `radius` (rad) apart, each once:
    ((K,) int64 rows into a, (K,) int64 columns into b, (K,) float64 angles in radians).

    A pair at distance 0 (a point exactly on another) is kept once whichever way the installed scipy's
    `sparse_distance_matrix` treats zero distances (its sparse-matrix outputs drop them in some versions and keep
    them in others): the pairs are taken from a nearest-neighbour query too and de-duplicated.
    """
    chord = 2.0 * math.sin(radius / 2.0)
    tree_b = cKDTree(b)
    found = cKDTree(a).sparse_distance_matrix(tree_b, chord, output_type="ndarray")
    dist, nearest = tree_b.query(a, k=1)
    on = np.flatnonzero(dist == 0.0)
    rows = np.concatenate([found["i"], on]).astype(np.int64)
    cols = np.concatenate([found["j"], nearest[on]]).astype(np.int64)
    chords = np.concatenate([found["v"], np.zeros(len(on))])
    _, first = np.unique(rows * len(b) + cols, return_index=True)
    angle = 2.0 * np.arcsin(np.clip(chords[first] / 2.0, 0.0, 1.0))
    return rows[first], cols[first], angle


def _validate(directions: np.ndarray, face_size: int, fwhm: float, radius: float | None) -> tuple:
    d = np.asarray(directions, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 3 or not np.all(np.isfinite(d)):
        raise ValueError(f"directions must be a finite (N, 3) array, got shape {d.shape}")
    norms = np.linalg.norm(d, axis=1)
    if np.any(np.abs(norms - 1.0) > 1e-6):
        raise ValueError("directions must be unit vectors")
    if not isinstance(face_size, (int, np.integer)) or face_size < 8:
        raise ValueError(f"face_size must be an integer >= 8, got {face_size!r}")
    if not (np.isfinite(fwhm) and 0 < fwhm < math.radians(MAX_FWHM_DEG)):
        raise ValueError(f"footprint FWHM must be in (0, {MAX_FWHM_DEG:g}) degrees, "
                         f"got {float(np.degrees(fwhm)):g} degrees")
    radius = fwhm if radius is None else float(radius)
    if not (np.isfinite(radius) and 0 < radius < np.pi / 2):
        raise ValueError(f"footprint radius must be in (0, 90) degrees, got {float(np.degrees(radius)):g} degrees")
    return d, int(face_size), float(fwhm), radius


def build_matrix(directions: np.ndarray, face_size: int, fwhm: float, radius: float | None = None) -> sp.csr_matrix:
    """(N_dirs, 6*face_size**2) float32 CSR matrix of normalised footprint weights (rows sum to 1).

    directions: (N, 3) unit vectors in the cube's frame; fwhm, radius: radians. Texel columns follow the
    atlas readback order of `cubemap.atlas_directions`.
    """
    d, n, fwhm, radius = _validate(directions, face_size, fwhm, radius)
    rows, cols, angle = pairs_within(d, atlas_directions(n), radius)
    w = gaussian_weight(angle, fwhm) * atlas_solid_angles(n)[cols]
    m = sp.csr_matrix((w, (rows, cols)), shape=(len(d), 6 * n * n), dtype=np.float64)
    sums = np.asarray(m.sum(axis=1)).ravel()
    if np.any(sums <= 0):
        raise ValueError("footprint radius is smaller than a texel: some LEDs see no texel; raise face_size")
    m = sp.diags(1.0 / sums) @ m
    m = m.tocsr().astype(np.float32)
    m.sort_indices()
    return m


def cache_dir() -> Path:
    """Where footprint matrices are cached: $ANTARIUM_CACHE or ~/.cache/antarium."""
    return Path(os.environ.get("ANTARIUM_CACHE", Path.home() / ".cache" / "antarium"))


def _load_cached(path: Path, n_rows: int, n_cols: int) -> sp.csr_matrix | None:
    """The (n_rows, n_cols) float32 CSR matrix cached at `path`, or None when the file is missing, unreadable
    (truncated, empty, not an npz: any exception numpy or zipfile raise) or holds arrays of other shapes or dtypes."""
    try:
        with np.load(path, allow_pickle=False) as z:
            data, indices, indptr, shape = z["data"], z["indices"], z["indptr"], z["shape"]
    except Exception:  # missing, or corrupt: it raises whatever its corruption trips (BadZipFile, EOFError, ...)
        return None
    if (shape.shape != (2,) or tuple(shape.tolist()) != (n_rows, n_cols) or data.dtype != np.float32
            or data.ndim != 1 or indices.ndim != 1 or indptr.shape != (n_rows + 1,) or len(data) != len(indices)
            or not np.issubdtype(indices.dtype, np.integer) or not np.issubdtype(indptr.dtype, np.integer)):
        return None
    m = sp.csr_matrix((data, indices, indptr), shape=(n_rows, n_cols))
    try:
        m.check_format(full_check=True)
    except ValueError:
        return None
    return m


def cached_matrix(directions: np.ndarray, face_size: int, fwhm: float, radius: float | None = None) -> sp.csr_matrix:
    """`build_matrix`, memoised on disk by a hash of all inputs. A cache file that cannot be read or does not hold
    a (N_dirs, 6*face_size**2) float32 CSR matrix is rebuilt and replaced (written to a temporary file, flushed to
    disk, then renamed over it)."""
    d, n, fwhm, radius = _validate(directions, face_size, fwhm, radius)
    h = hashlib.sha256(np.ascontiguousarray(d).tobytes())
    h.update(np.array([n, fwhm, radius, _CACHE_VERSION], dtype=np.float64).tobytes())
    path = cache_dir() / f"footprint-{h.hexdigest()[:24]}.npz"
    m = _load_cached(path, len(d), 6 * n * n)
    if m is not None:
        return m
    m = build_matrix(d, n, fwhm, radius)
    tmp = path.with_name(path.name + f".{os.getpid()}.tmp.npz")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(tmp, "wb") as f:
            np.savez(f, data=m.data, indices=m.indices, indptr=m.indptr, shape=np.array(m.shape))
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except OSError:  # a read-only home only costs the rebuild next time
        tmp.unlink(missing_ok=True)
    return m


def reference_sample(atlas: np.ndarray, directions: np.ndarray, fwhm: float, radius: float | None = None) -> np.ndarray:
    """Pure-numpy footprint integral by brute force over every texel (slow; for tests).

    atlas: (6*N*N, C) texel values in atlas order; directions: (M, 3) unit vectors; returns (M, C) float64.
    """
    atlas = np.asarray(atlas, dtype=np.float64)
    n = int(round(np.sqrt(atlas.shape[0] / 6)))
    d, n, fwhm, radius = _validate(directions, n, fwhm, radius)
    texels = atlas_directions(n)
    omega = atlas_solid_angles(n)
    out = np.empty((len(d), atlas.shape[1]))
    for start in range(0, len(d), 64):
        cosang = np.clip(d[start : start + 64] @ texels.T, -1.0, 1.0)
        angle = np.arccos(cosang)
        w = np.where(angle <= radius, gaussian_weight(angle, fwhm), 0.0) * omega
        out[start : start + 64] = (w @ atlas) / w.sum(axis=1, keepdims=True)
    return out
