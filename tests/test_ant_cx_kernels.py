"""The compiled compass and CX steps equal the straightforward numpy models (the pre-kernel code, kept here as the
reference) on fixed inputs: same seed, same noise stream, same rates within rounding."""

import math

import numpy as np
import pytest
from scipy.special import expit

from antarium.ant.central_complex import _CPU4_TO_CPU1, _PONTINE, _W_TB1_TB1, N_COLUMNS, PREFS, CentralComplex, CXParams
from antarium.ant.compass import SkyCompass, e_vectors_from_polarisers


class ReferenceCX:
    """Stone 2017's CX, one numpy call per layer (the straightforward model)."""

    def __init__(self, p: CXParams):
        self.p, self.rng = p, np.random.default_rng(p.seed)
        self.tb1, self.cpu4, self.cpu1 = np.zeros(8), np.full(16, 0.5), np.zeros(16)

    def sig(self, v, slope, bias):
        out = expit(v * slope - bias)
        if self.p.noise > 0:
            out = out + self.rng.normal(0.0, self.p.noise, out.shape)
        return np.clip(out, 0.0, 1.0)

    def compass(self, heading):
        p = self.p
        tl2 = self.sig(np.cos(heading - np.tile(PREFS, 2)), p.tl2_slope, p.tl2_bias)
        cl1 = self.sig(-tl2, p.cl1_slope, p.cl1_bias)
        drive = p.prop_cl1 * (cl1[:8] + cl1[8:]) - (1 - p.prop_cl1) * _W_TB1_TB1 @ self.tb1
        self.tb1 = self.sig(drive, p.tb1_slope, p.tb1_bias)

    def integrate(self, speed):
        p = self.p
        tn2 = np.full(2, speed * math.cos(math.pi / 4))
        if p.noise > 0:
            tn2 = tn2 + self.rng.normal(0.0, p.noise, 2)
        tn2 = np.clip(tn2, 0.0, 1.0)
        update = np.clip(np.repeat(tn2, 8) - np.tile(self.tb1, 2), 0.0, 1.0) * p.cpu4_gain
        mem = self.cpu4 + update - p.cpu4_decay_bias * p.cpu4_gain
        mem -= p.leak * (mem - 0.5)
        self.cpu4 = np.clip(mem, 0.0, 1.0)

    def steering(self, extra=None, k=1.0):
        p = self.p
        cpu4 = self.sig(self.cpu4, p.cpu4_slope, p.cpu4_bias)
        pontine = self.sig(cpu4, p.pontine_slope, p.pontine_bias)
        memory = 0.5 * cpu4[_CPU4_TO_CPU1]
        memory = memory - 0.5 * pontine[_PONTINE]
        if extra is not None:
            memory = k * memory + (1.0 - k) * (0.5 * extra[_CPU4_TO_CPU1] - 0.5 * extra[_PONTINE])
        self.cpu1 = self.sig(memory - np.tile(self.tb1, 2), p.cpu1_slope, p.cpu1_bias)

    def home_vector(self):
        z = ((np.roll(self.cpu4[:8], 1) + np.roll(self.cpu4[8:], -1)) * np.exp(1j * PREFS)).sum()
        return float(np.angle(z)), float(abs(z))


@pytest.mark.parametrize("params", [CXParams(), CXParams(noise=0.0), CXParams(leak=0.01, seed=3)])
def test_compiled_cx_equals_the_straightforward_model(params):
    rng = np.random.default_rng(1)
    cx, ref = CentralComplex(params), ReferenceCX(params)
    for i in range(700):  # > one noise block
        heading, speed = rng.uniform(-math.pi, math.pi), rng.uniform(0, 1)
        extra = rng.uniform(0, 1, 16) if i % 3 == 0 else None
        cx.compass(heading), ref.compass(heading)
        cx.integrate(speed), ref.integrate(speed)
        cx.steering(extra, 0.8), ref.steering(extra, 0.8)
        np.testing.assert_allclose(cx.tb1, ref.tb1, atol=1e-9)
        np.testing.assert_allclose(cx.cpu4, ref.cpu4, atol=1e-9)
        np.testing.assert_allclose(cx.cpu1, ref.cpu1, atol=1e-9)
    np.testing.assert_allclose(cx.home_vector(), ref.home_vector(), atol=1e-9)
    assert cx.tb1.shape == (N_COLUMNS,)


def test_compiled_compass_fit_equals_the_straightforward_sums():
    from antarium.ant.cx_kernels import compass_fit
    from antarium.bench.ant_cx import sky_frames
    from antarium.geometry import load_dome

    dome = load_dome()
    compass = SkyCompass.from_dome(dome)
    frames, angles = sky_frames(dome, 2)
    rng = np.random.default_rng(2)
    angles = angles + rng.normal(0, 0.2, angles.shape)  # not a perfect sky: the fit has a residual
    a = angles.reshape(-1)
    for f in frames:
        drive = f[compass.pixels].astype(np.float64) * compass._scale[:, None]
        pol, total = drive[:, 1], drive.sum(1)
        e = e_vectors_from_polarisers(compass._dirs, a[compass._uv_slot], compass._axes)
        lit, pol_lit, total_lit, m, gradient = compass_fit(f, compass.pixels, compass._scale, compass._uv_slot, a,
                                                           compass._px, compass._py, compass._dirs, 0.01, 0.05)
        on = total > 0.01
        sky = on & (pol >= 0.05 * total)
        assert lit == on.sum()
        assert pol_lit == pytest.approx(pol[on].sum(), rel=1e-12)
        assert total_lit == pytest.approx(total[on].sum(), rel=1e-12)
        np.testing.assert_allclose(m, (e * pol[:, None]).T @ e, rtol=1e-10, atol=1e-12)
        np.testing.assert_allclose(gradient, (total[sky] - total[sky].mean()) @ compass._dirs[sky], rtol=1e-10,
                                   atol=1e-12)


def _reference_flow(of, before, after):
    """The straightforward numpy Lucas-Kanade (the pre-kernel `OpticFlow.flow`)."""
    i0 = before[of.pixels].sum(axis=1, dtype=np.float64) * of._scale
    i1 = after[of.pixels].sum(axis=1, dtype=np.float64) * of._scale
    mean = 0.5 * (i0 + i1)
    grad = np.einsum("mjk,mk->mj", of._pinv, mean[of._nb] - mean[:, None])
    dt = i1 - i0
    g = np.concatenate([grad[:, None, :], grad[of._nb]], axis=1)
    t = np.concatenate([dt[:, None], dt[of._nb]], axis=1)
    gtg = np.einsum("mki,mkj->mij", g, g) + 1e-9 * np.eye(2)
    gtt = np.einsum("mki,mk->mi", g, t)
    return -np.linalg.solve(gtg, gtt[..., None])[..., 0]


def test_compiled_flow_equals_the_straightforward_lucas_kanade():
    from antarium.ant.optic_flow import OpticFlow
    from antarium.geometry import load_dome

    dome = load_dome()
    of = OpticFlow.from_dome(dome)
    d = np.asarray(dome.directions, np.float64)
    az, el = np.arctan2(d[:, 1], d[:, 0]), np.arcsin(d[:, 2] / np.linalg.norm(d, axis=1))

    def frame(shift):  # a smooth pattern turned by `shift` rad
        v = 0.5 + 0.4 * np.sin(5 * (az - shift)) * np.cos(3 * el)
        return np.repeat((v * 30000).astype(np.uint16)[:, None], 2, axis=1)

    before, after = frame(0.0), frame(0.02)
    ref = _reference_flow(of, before, after)
    np.testing.assert_allclose(of.flow(before, after), ref, rtol=1e-7, atol=1e-9 * np.abs(ref).max())
    need = np.zeros(of.pixels.size, bool)
    need[::7] = True
    part = of.flow(before, after, need)
    np.testing.assert_allclose(part[need], ref[need], rtol=1e-7, atol=1e-9 * np.abs(ref).max())
    assert not part[~need].any()


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5])
def test_compiled_filter_turn_equals_the_numpy_formula(yaw):
    from antarium.ant.optic_flow import FlowParams, OpticFlow
    from antarium.geometry import load_dome

    dome = load_dome()
    p = FlowParams(react_distance=100.0)
    of = OpticFlow.from_dome(dome, p)
    d = np.asarray(dome.directions, np.float64)
    az, el = np.arctan2(d[:, 1], d[:, 0]), np.arcsin(d[:, 2] / np.linalg.norm(d, axis=1))

    def frame(shift):  # a pattern brighter towards azimuth 0.3, turned by `shift` rad
        v = 0.5 + 0.4 * np.sin(5 * (az - shift)) * np.cos(3 * el) * (1 + 0.5 * np.cos(az - 0.3))
        return np.repeat((v * 30000).astype(np.uint16)[:, None], 2, axis=1)

    before, after = frame(0.0), frame(0.01)
    flow = of.flow(before, after)
    rel = np.remainder(of.azimuth - yaw + math.pi, math.tau) - math.pi
    forward = np.array([math.cos(yaw), math.sin(yaw), 0.0])
    e3 = -(forward - (of.directions @ forward)[:, None] * of.directions)
    expected = np.stack([(e3 * of.east).sum(1), (e3 * of.north).sum(1)], axis=1)
    norm2 = (expected ** 2).sum(1)
    ok = (np.abs(rel) <= math.radians(p.frontal_deg)) & (norm2 > 0.05)
    near = np.maximum((flow * expected).sum(1) / norm2, 0.0) / 0.01
    near = np.where(near > 1.0 / p.react_distance, near, 0.0)
    left, right = near[ok & (rel > 0)].sum(), near[ok & (rel < 0)].sum()
    turn, trace = of.avoid(before, after, yaw, 0.01)
    assert left + right > 0
    assert trace["flow_left"] == pytest.approx(left, rel=1e-9)
    assert trace["flow_right"] == pytest.approx(right, rel=1e-9)
    assert turn == pytest.approx(np.clip(-p.gain * (left - right) / (left + right + p.half_nearness),
                                         -p.max_turn, p.max_turn), rel=1e-9, abs=1e-12)


def test_sparse_mbon_read_equals_novelty():
    from antarium.ant.navigation import CXMBModel, CXMBParams

    class FakeView:  # the lowest seam: a view's PN vector
        def __init__(self, pn):
            self.pn = pn

        def pns(self, angles):
            return self.pn[None, :]

    rng = np.random.default_rng(4)
    model = CXMBModel(800, CXMBParams(n_kc=2000))
    for j in range(N_COLUMNS):
        model.mbons[f"tb1_{j}"].learn(model.kc.active(rng.uniform(0, 1, (j + 1, 800))))
    view = FakeView(rng.uniform(0, 1, 800).astype(np.float32))
    active = model.kc.active(view.pns((0.0,)))
    expected = [model.mbons[f"tb1_{j}"].novelty(active)[0] for j in range(N_COLUMNS)]
    got = model.responses(view)
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    assert 0 < got.min() < got.max() <= 1


def test_compiled_frontal_field_equals_numpy_remainder():
    from antarium.ant.flow_kernels import frontal_field

    az = np.linspace(-math.pi, math.pi, 2001)
    east = np.stack([-np.sin(az), np.cos(az), np.zeros_like(az)], axis=1)
    north = np.tile([0.0, 0.0, 1.0], (az.size, 1))
    for yaw in (0.0, 1.0, -2.5, 7.0, -13.0, math.pi, -math.pi):
        rel, *_ = frontal_field(az, east, north, yaw, math.pi / 2)
        np.testing.assert_array_equal(rel, np.remainder(az - yaw + math.pi, math.tau) - math.pi)


def test_k_zero_leaves_the_whole_cpu4_pathway_out():
    """k weighs all that CPU1 gets from CPU4, the Pontine cells' share too: with k = 0 two different memories
    steer alike (the MBONs alone), with k = 1 the extra input has no effect (the CX alone)."""
    extra = np.random.default_rng(2).uniform(0, 1, 16)
    cpu1 = {}
    for heading in (0.0, 2.0):
        cx = CentralComplex(CXParams(noise=0.0))
        for _ in range(300):
            cx.step(heading, 0.8)
        cx.tb1[:] = np.linspace(0.1, 0.9, N_COLUMNS)  # the same heading now: only the memories differ
        cpu1[heading, 0.0] = cx.steering(extra, 0.0).copy()
        cpu1[heading, 1.0] = cx.steering(extra, 1.0).copy()
        assert np.array_equal(cpu1[heading, 1.0], cx.steering().copy())
    np.testing.assert_allclose(cpu1[0.0, 0.0], cpu1[2.0, 0.0], rtol=0, atol=1e-12)
    assert np.abs(cpu1[0.0, 1.0] - cpu1[2.0, 1.0]).max() > 0.05
