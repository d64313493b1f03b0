"""Compiled Lucas-Kanade flow on the dome's pixel lattice (numba), for `optic_flow.OpticFlow`: intensities of the
band's pixels, their tangent-plane gradients from the precomputed neighbour tables, and the flow solved only for
the pixels asked for. Cached per machine; imported lazily (so `import antarium` stays free of numba)."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def band_intensity(leds, pixels, scale):
    """(M,) intensity (green + blue, 1 = the farthest LED at full) of the band's pixels in an (N, 2) LED frame."""
    out = np.empty(pixels.shape[0])
    for i in range(pixels.shape[0]):
        out[i] = (np.float64(leds[pixels[i], 0]) + np.float64(leds[pixels[i], 1])) * scale[i]
    return out


@njit(cache=True)
def lucas_kanade(i0, i1, nb, pinv, need):
    """(M, 2) flow (east, north; rad per frame) of the band's M pixels between two intensity vectors (M,), zero
    where `need` (M,) bool is False.

    nb (M, k) neighbour places in the band; pinv (M, 2, k) the least-squares gradient from the neighbours'
    differences. Per needed pixel: gradient g of the mean of the two frames, time difference t, flow =
    -(sum g g^T + 1e-9 I)^-1 sum g t over the pixel and its neighbours."""
    m, k = nb.shape
    dt = i1 - i0
    mean = 0.5 * (i0 + i1)
    # gradients where a needed pixel or one of its neighbours needs them
    want = np.zeros(m, np.bool_)
    for i in range(m):
        if need[i]:
            want[i] = True
            for j in range(k):
                want[nb[i, j]] = True
    grad = np.zeros((m, 2))
    for i in range(m):
        if want[i]:
            ge = 0.0
            gn = 0.0
            for j in range(k):
                diff = mean[nb[i, j]] - mean[i]
                ge += pinv[i, 0, j] * diff
                gn += pinv[i, 1, j] * diff
            grad[i, 0] = ge
            grad[i, 1] = gn
    flow = np.zeros((m, 2))
    for i in range(m):
        if not need[i]:
            continue
        a00 = grad[i, 0] * grad[i, 0]
        a01 = grad[i, 0] * grad[i, 1]
        a11 = grad[i, 1] * grad[i, 1]
        b0 = grad[i, 0] * dt[i]
        b1 = grad[i, 1] * dt[i]
        for j in range(k):
            n = nb[i, j]
            a00 += grad[n, 0] * grad[n, 0]
            a01 += grad[n, 0] * grad[n, 1]
            a11 += grad[n, 1] * grad[n, 1]
            b0 += grad[n, 0] * dt[n]
            b1 += grad[n, 1] * dt[n]
        a00 += 1e-9
        a11 += 1e-9
        det = a00 * a11 - a01 * a01
        flow[i, 0] = -(a11 * b0 - a01 * b1) / det
        flow[i, 1] = -(a00 * b1 - a01 * b0) / det
    return flow


@njit(cache=True)
def _wrap(x):
    """x % tau, bit for bit as numpy's remainder (fmod, then + tau for a negative rest), without fmod (slow) in the
    one-period cases: exact subtractions there (Sterbenz)."""
    tau = 2 * np.pi
    if 0.0 <= x < tau:
        return x
    if tau <= x < 2 * tau:
        return x - tau
    if -tau < x < 0.0:
        return x + tau
    return x % tau


@njit(cache=True)
def frontal_field(azimuth, east, north, yaw, frontal):
    """For an ant facing dome azimuth `yaw` (rad): each band pixel's body azimuth rel (M,) in [-pi, pi), the
    expected flow (M, 2) of a unit forward translation (-f projected on east, north: both normal to the pixel
    direction), its squared norm (M,) and whether the pixel counts (M,) bool: |rel| <= `frontal` rad and
    norm^2 > 0.05."""
    m = azimuth.shape[0]
    rel = np.empty(m)
    expected = np.empty((m, 2))
    norm2 = np.empty(m)
    ok = np.empty(m, np.bool_)
    fx, fy = np.cos(yaw), np.sin(yaw)
    for i in range(m):
        r = _wrap(azimuth[i] - yaw + np.pi) - np.pi
        e = -(east[i, 0] * fx + east[i, 1] * fy)
        n = -(north[i, 0] * fx + north[i, 1] * fy)
        rel[i] = r
        expected[i, 0] = e
        expected[i, 1] = n
        norm2[i] = e * e + n * n
        ok[i] = abs(r) <= frontal and norm2[i] > 0.05
    return rel, expected, norm2, ok


@njit(cache=True)
def filter_sides(flow, expected, norm2, rel, ok, travelled, react_distance):
    """(left, right) summed nearness (1/m) of the counting pixels: the flow's projection on the expected flow over
    its squared norm, divided by `travelled` m, kept where above 1 / `react_distance`; left: rel > 0."""
    left = 0.0
    right = 0.0
    for i in range(flow.shape[0]):
        if not ok[i]:
            continue
        near = max((flow[i, 0] * expected[i, 0] + flow[i, 1] * expected[i, 1]) / max(norm2[i], 1e-12), 0.0)
        near = near / max(travelled, 1e-6)
        if near <= 1.0 / react_distance:
            continue
        if rel[i] > 0.0:
            left += near
        elif rel[i] < 0.0:
            right += near
    return left, right
