"""Compiled per-decision loops (numba) of the sky compass and the central complex: one call each instead of dozens
of small numpy calls. Compiled once per machine (cached next to this file or in NUMBA_CACHE_DIR), imported lazily
by `compass.SkyCompass` and `central_complex.CentralComplex` (so `import antarium` stays free of numba).

Every rate is `clip(sigmoid(v * slope - bias) + noise, 0, 1)`; the noise values are passed in (drawn in blocks by
the caller, in the order the straightforward model draws them), so the compiled step equals it on fixed inputs.
Column layouts are those of `central_complex` (TB1 column j prefers j * 45 deg; CPU4/CPU1 halves of 8).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit


@njit(cache=True)
def eigh3(m):
    """np.linalg.eigh of the (3, 3) symmetric e-vector scatter (the same LAPACK routine, without numpy's per-call
    cost): eigenvalues ascending (3,), eigenvectors as columns (3, 3)."""
    return np.linalg.eigh(m)


@njit(cache=True)
def compass_fit(leds, pixels, scale, slots, angles, px, py, dirs, min_intensity, min_degree):
    """Dorsal-rim sums for one LED frame: (lit pixels, polarised sum of the lit, total sum of the lit, (3, 3)
    e-vector scatter sum_i P_i e_i e_i^T, (3,) brightness gradient sum_sky (I_i - mean_sky I) d_i).
    The gradient is the sky's alone: over the lit pixels polarised at least `min_degree` (objects in the scene
    are unpolarised) about their mean intensity, so pixels an object hides pull it to no side.

    leds (N, 2) uint16; pixels (M,) int64 LED rows; scale (M,) 1 / (65535 gain); slots (M,) places in the flat
    polariser angle array `angles` (rad); px, py (M, 3) the panel's x and y axes projected normal to the pixel
    direction (so e = cos a px + sin a py, normalised); dirs (M, 3) unit pixel directions."""
    m = np.zeros((3, 3))
    bright = np.zeros(3)
    dir_sum = np.zeros(3)
    lit = 0
    sky = 0
    total_sky = 0.0
    pol_lit = 0.0
    total_lit = 0.0
    for i in range(pixels.shape[0]):
        row = pixels[i]
        pol = leds[row, 1] * scale[i]
        total = leds[row, 0] * scale[i] + pol
        if total > min_intensity:
            lit += 1
            pol_lit += pol
            total_lit += total
            if pol >= min_degree * total:
                sky += 1
                total_sky += total
                for k in range(3):
                    bright[k] += total * dirs[i, k]
                    dir_sum[k] += dirs[i, k]
        a = angles[slots[i]]
        c = math.cos(a)
        s = math.sin(a)
        e0 = c * px[i, 0] + s * py[i, 0]
        e1 = c * px[i, 1] + s * py[i, 1]
        e2 = c * px[i, 2] + s * py[i, 2]
        norm = max(math.sqrt(e0 * e0 + e1 * e1 + e2 * e2), 1e-12)
        w = pol / (norm * norm)
        m[0, 0] += w * e0 * e0
        m[0, 1] += w * e0 * e1
        m[0, 2] += w * e0 * e2
        m[1, 1] += w * e1 * e1
        m[1, 2] += w * e1 * e2
        m[2, 2] += w * e2 * e2
    m[1, 0] = m[0, 1]
    m[2, 0] = m[0, 2]
    m[2, 1] = m[1, 2]
    mean = total_sky / max(sky, 1)
    return lit, pol_lit, total_lit, m, bright - mean * dir_sum


@njit(cache=True)
def degree_excess(leds, pixels, scale, dirs, sun, min_intensity, min_degree):
    """Root mean square excess of the sky pixels' (lit, polarised at least `min_degree`) degrees of polarisation
    over single scattering's pattern q = (1 - c^2) / (1 + c^2), c = d . `sun` (3,) unit, as a share of p_max, the
    median of degree / q over the sky pixels with q >= 0.3; 0.0 without such pixels. Arguments as `compass_fit`."""
    n = pixels.shape[0]
    degree = np.empty(n)
    pattern = np.empty(n)
    ratio = np.empty(n)
    sky = 0
    clear = 0
    for i in range(n):
        row = pixels[i]
        pol = leds[row, 1] * scale[i]
        total = leds[row, 0] * scale[i] + pol
        if total > min_intensity and pol >= min_degree * total:
            c = dirs[i, 0] * sun[0] + dirs[i, 1] * sun[1] + dirs[i, 2] * sun[2]
            q = (1.0 - c * c) / (1.0 + c * c)
            degree[sky] = pol / total
            pattern[sky] = q
            sky += 1
            if q >= 0.3:
                ratio[clear] = pol / total / q
                clear += 1
    if clear == 0:
        return 0.0
    p_max = np.median(ratio[:clear])
    excess = 0.0
    for i in range(sky):
        e = max(0.0, degree[i] - p_max * pattern[i])
        excess += e * e
    return math.sqrt(excess / sky) / p_max


@njit(cache=True)
def _rate(v, slope, bias, z):
    return min(1.0, max(0.0, 1.0 / (1.0 + math.exp(-(v * slope - bias))) + z))


@njit(cache=True)
def cx_compass(heading, tb1, w_tb1, prefs, prm, z):
    """TL2 -> CL1 -> TB1 in place for `heading` (rad). prm: the `CXParams` as `central_complex.param_vector`;
    z (40,) noise: TL2 (16), CL1 (16), TB1 (8)."""
    n = tb1.shape[0]
    cl1_sum = np.zeros(n)
    for i in range(2 * n):
        tl2 = _rate(math.cos(heading - prefs[i % n]), prm[1], prm[2], z[i])
        cl1_sum[i % n] += _rate(-tl2, prm[3], prm[4], z[2 * n + i])
    drive = np.empty(n)
    for j in range(n):
        inhibition = 0.0
        for k in range(n):
            inhibition += w_tb1[j, k] * tb1[k]
        drive[j] = prm[7] * cl1_sum[j] - (1.0 - prm[7]) * inhibition
    for j in range(n):
        tb1[j] = _rate(drive[j], prm[5], prm[6], z[4 * n + j])


@njit(cache=True)
def cx_integrate(speed, tb1, cpu4, prm, z):
    """CPU4 memory update in place for forward `speed` (0..1); z (2,) the TN2 noise."""
    n = tb1.shape[0]
    gain = prm[10]
    for i in range(2 * n):
        tn2 = min(1.0, max(0.0, speed * math.cos(math.pi / 4) + z[i // n]))
        mem = cpu4[i] + min(1.0, max(0.0, tn2 - tb1[i % n])) * gain - prm[11] * gain
        mem -= prm[12] * (mem - 0.5)
        cpu4[i] = min(1.0, max(0.0, mem))


@njit(cache=True)
def cx_steering(tb1, cpu4, cpu1, extra, k, use_extra, to_cpu1, pontine_of, prm, z):
    """CPU1 in place from the memory, TB1 and (use_extra) `extra` (16,) weighed 1 - k against all that comes from
    CPU4 (its direct input and the Pontine cells', weight k: k = 0 leaves CPU4 out); `extra` enters centred as CPU4
    does (0.5 at the shifted column - 0.5 at the Pontine column); z (48,) noise: CPU4 output (16), Pontine (16),
    CPU1 (16)."""
    n2 = cpu4.shape[0]
    n = n2 // 2
    out4 = np.empty(n2)
    pontine = np.empty(n2)
    for i in range(n2):
        out4[i] = _rate(cpu4[i], prm[8], prm[9], z[i])
    for i in range(n2):
        pontine[i] = _rate(out4[i], prm[13], prm[14], z[n2 + i])
    for i in range(n2):
        memory = 0.5 * out4[to_cpu1[i]] - 0.5 * pontine[pontine_of[i]]
        if use_extra:
            # centred as CPU4's input is (its Pontine column subtracted): a flat input adds no turn
            memory = k * memory + (1.0 - k) * (0.5 * extra[to_cpu1[i]] - 0.5 * extra[pontine_of[i]])
        drive = memory - tb1[i % n]
        cpu1[i] = _rate(drive, prm[15], prm[16], z[2 * n2 + i])


@njit(cache=True)
def cx_home_vector(cpu4, prefs):
    """(direction rad, strength) of the shifted CPU4 halves' population vector."""
    n = prefs.shape[0]
    x = 0.0
    y = 0.0
    for j in range(n):
        v = cpu4[(j - 1) % n] + cpu4[n + (j + 1) % n]
        x += v * math.cos(prefs[j])
        y += v * math.sin(prefs[j])
    return math.atan2(y, x), math.hypot(x, y)
