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


@njit(cache=True, inline="always")
def _gradients(i0, i1, nb, pinv, need):
    """The time differences dt (M,) and the gradients (M, 2) of the frames' mean where a needed pixel or one of its
    neighbours needs them (zero elsewhere): nb (M, k) neighbour places, pinv (M, 2, k) least squares from the
    neighbours' differences."""
    m, k = nb.shape
    dt = i1 - i0
    mean = 0.5 * (i0 + i1)
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
    return dt, grad


@njit(cache=True, inline="always")
def _flow_at(i, nb, dt, grad):
    """The flow (east, north) of pixel i: -(sum g g^T + 1e-9 I)^-1 sum g t over it and its neighbours."""
    a00 = grad[i, 0] * grad[i, 0]
    a01 = grad[i, 0] * grad[i, 1]
    a11 = grad[i, 1] * grad[i, 1]
    b0 = grad[i, 0] * dt[i]
    b1 = grad[i, 1] * dt[i]
    for j in range(nb.shape[1]):
        n = nb[i, j]
        a00 += grad[n, 0] * grad[n, 0]
        a01 += grad[n, 0] * grad[n, 1]
        a11 += grad[n, 1] * grad[n, 1]
        b0 += grad[n, 0] * dt[n]
        b1 += grad[n, 1] * dt[n]
    a00 += 1e-9
    a11 += 1e-9
    det = a00 * a11 - a01 * a01
    return -(a11 * b0 - a01 * b1) / det, -(a00 * b1 - a01 * b0) / det


@njit(cache=True)
def lucas_kanade(i0, i1, nb, pinv, need):
    """(M, 2) flow (east, north; rad per frame) of the band's M pixels between two intensity vectors (M,), zero
    where `need` (M,) bool is False.

    nb (M, k) int16/32 neighbour places in the band; pinv (M, 2, k) the least-squares gradient from the neighbours'
    differences. Per needed pixel: gradient g of the mean of the two frames, time difference t, flow =
    -(sum g g^T + 1e-9 I)^-1 sum g t over the pixel and its neighbours."""
    dt, grad = _gradients(i0, i1, nb, pinv, need)
    flow = np.zeros((nb.shape[0], 2))
    for i in range(nb.shape[0]):
        if need[i]:
            flow[i, 0], flow[i, 1] = _flow_at(i, nb, dt, grad)
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


@njit(cache=True, inline="always")
def _frontal_pixel(i, azimuth, east, north, yaw, fx, fy, frontal):
    """Pixel i's body azimuth rel in [-pi, pi) for an ant facing `yaw` (forward (fx, fy)), the expected flow
    (east, north) of a unit forward translation, its squared norm, and whether the pixel counts (|rel| <= frontal
    and norm^2 > 0.05)."""
    r = _wrap(azimuth[i] - yaw + np.pi) - np.pi
    e = -(east[i, 0] * fx + east[i, 1] * fy)
    n = -(north[i, 0] * fx + north[i, 1] * fy)
    norm2 = e * e + n * n
    return r, e, n, norm2, abs(r) <= frontal and norm2 > 0.05


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
        rel[i], expected[i, 0], expected[i, 1], norm2[i], ok[i] = _frontal_pixel(i, azimuth, east, north, yaw, fx,
                                                                                   fy, frontal)
    return rel, expected, norm2, ok


@njit(cache=True, inline="always")
def _nearness(fe, fn, e, n, norm2, travelled):
    """A pixel's nearness (1/m): its flow's projection on the expected flow over its squared norm, divided by
    `travelled` m, never below 0."""
    near = max((fe * e + fn * n) / max(norm2, 1e-12), 0.0)
    return near / max(travelled, 1e-6)


@njit(cache=True)
def filter_turn_sides(i0, i1, nb, pinv, azimuth, east, north, yaw, frontal, travelled, react_distance):
    """(left, right) summed nearness (1/m) of the pixels `frontal_field` counts for an ant facing `yaw` that walked
    `travelled` m, from their `lucas_kanade` flow between band intensities i0 and i1 (M,), without the (M, 2)
    arrays: each pixel's nearness (`_nearness`) kept where above 1 / `react_distance`; left: rel > 0."""
    m = azimuth.shape[0]
    fx, fy = np.cos(yaw), np.sin(yaw)
    ok = np.empty(m, np.bool_)
    for i in range(m):
        ok[i] = _frontal_pixel(i, azimuth, east, north, yaw, fx, fy, frontal)[4]
    dt, grad = _gradients(i0, i1, nb, pinv, ok)
    left = 0.0
    right = 0.0
    for i in range(m):
        if not ok[i]:
            continue
        r, e, n, norm2, _ = _frontal_pixel(i, azimuth, east, north, yaw, fx, fy, frontal)
        fe, fn = _flow_at(i, nb, dt, grad)
        near = _nearness(fe, fn, e, n, norm2, travelled)
        if near <= 1.0 / react_distance:
            continue
        if r > 0.0:
            left += near
        elif r < 0.0:
            right += near
    return left, right
