"""The per-decision paths of the eye, the KCs, the optic flow and the compass after their speed-ups (compiled
frame reads and scan columns, one fused flow pass, narrow index tables, compiled 3 x 3 eigh, scalar clip): the
same results as the numpy formulas they replace, bit for bit where the operations are the same."""

import math

import numpy as np
import pytest

from antarium.geometry import load_dome


@pytest.fixture(scope="module")
def dome():
    return load_dome()


@pytest.mark.parametrize("channel", ["green", "blue", "uv"])
def test_eye_reads_the_frame_as_the_numpy_gather_does(dome, channel):
    from antarium.ant.eye import Eye, EyeParams

    eye = Eye.from_dome(dome, EyeParams(channel=channel))
    rng = np.random.default_rng(1)
    for frame in (rng.integers(0, 65536, size=(dome.directions.shape[0], 2), dtype=np.uint16),
                  np.full((dome.directions.shape[0], 2), 65535, np.uint16),
                  rng.integers(0, 65536, size=(dome.directions.shape[0], 2)).astype(np.float64)):
        ref = frame.reshape(-1)[eye._flat].sum(axis=1, dtype=np.float32) * eye._scale
        got = eye.intensities(frame)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, ref)
    with pytest.raises(ValueError, match="shape"):
        eye.intensities(np.zeros((10, 2), np.uint16))


def test_scan_columns_equal_the_numpy_formula():
    from antarium.ant.eye import View

    rng = np.random.default_rng(2)
    band = rng.random((16, 300), dtype=np.float32)
    for yaw, scale in ((0.0, 0.5), (0.37, 3.0), (-2.0, 100.0), (1e4, 1.0)):
        view = View(band, 6, 50, yaw)
        angles = np.concatenate([[0.0, -0.0, math.pi, -math.tau], rng.normal(size=57) * scale])
        turned = angles + yaw
        pos = (np.arange(50) * 6)[None, :] + turned[:, None] / (math.tau / 300)
        i0 = np.floor(pos).astype(np.int64)
        w = (pos - i0).astype(np.float32)
        i0 %= 300
        got = view._columns(angles)
        for a, b in zip(got, (i0, (i0 + 1) % 300, w), strict=True):
            assert a.dtype == b.dtype
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("yaw", [0.0, 1.3, -2.9])
def test_fused_filter_pass_equals_the_frontal_field_the_flow_and_the_sum_in_order(dome, yaw):
    from antarium.ant.flow_kernels import frontal_field, lucas_kanade
    from antarium.ant.optic_flow import FlowParams, OpticFlow

    p = FlowParams(react_distance=50.0)
    of = OpticFlow.from_dome(dome, p)
    rng = np.random.default_rng(3)
    before = rng.integers(0, 30000, size=(dome.directions.shape[0], 2), dtype=np.uint16)
    after = np.clip(before.astype(np.int64) + rng.integers(-2000, 2000, size=before.shape), 0, 65535).astype(np.uint16)
    i0, i1 = of.intensity(before), of.intensity(after)
    rel, expected, norm2, ok = frontal_field(of.azimuth, of.east, of.north, yaw, math.radians(p.frontal_deg))
    flow = lucas_kanade(i0, i1, of._nb, of._pinv, ok)
    left = right = 0.0
    for i in np.flatnonzero(ok):  # the filter method's sum, pixel by pixel in the band's order
        near = max(float(flow[i] @ expected[i]) / max(norm2[i], 1e-12), 0.0) / 0.01
        if near > 1.0 / p.react_distance:
            left, right = (left + near, right) if rel[i] > 0 else (left, right + near) if rel[i] < 0 else (left, right)
    turn, trace = of.avoid_of(i0, i1, yaw, 0.01)
    assert left + right > 0
    assert (trace["flow_left"], trace["flow_right"]) == (left, right)


def test_index_tables_are_narrow_and_the_kernels_read_any_width_alike(dome):
    from antarium.ant.eye import Eye
    from antarium.ant.flow_kernels import lucas_kanade
    from antarium.ant.kc_kernel import Workspace
    from antarium.ant.mushroom_body import KenyonCells
    from antarium.ant.optic_flow import OpticFlow
    from antarium.ant.tables import index_table

    assert index_table([0, 32767], 32767).dtype == np.int16
    assert index_table([0, 32768], 32768).dtype == np.int32
    assert index_table(np.arange(6).reshape(2, 3).T, 6).flags.c_contiguous

    of = OpticFlow.from_dome(dome)
    assert of._nb.dtype == np.int16
    rng = np.random.default_rng(4)
    i0, i1 = rng.random(of.pixels.size), rng.random(of.pixels.size)
    need = rng.random(of.pixels.size) < 0.5
    np.testing.assert_array_equal(lucas_kanade(i0, i1, of._nb, of._pinv, need),
                                  lucas_kanade(i0, i1, of._nb.astype(np.int64), of._pinv, need))

    eye = Eye.from_dome(dome)
    view = eye.look(rng.integers(0, 65536, size=(dome.directions.shape[0], 2), dtype=np.uint16))
    assert eye._band._nb[0].dtype == np.int16
    x = rng.random(eye._sample.shape[1], dtype=np.float32)
    narrow = eye._band(x)
    eye._band._nb = (eye._band._nb[0].astype(np.int32), eye._band._nb[1])
    np.testing.assert_array_equal(eye._band(x), narrow)

    kc = KenyonCells(800, 2000, 10, 0.01, seed=5)
    pn = view.pns(np.linspace(-1, 1, 5))
    weights = rng.random((3, 2000)) < 0.7
    narrow_ws = Workspace(kc.pn_index, kc.k, 800)
    assert narrow_ws.pn_index.dtype == np.int16
    wide_ws = Workspace(kc.pn_index, kc.k, 800)
    wide_ws.pn_index = wide_ws.pn_index.astype(np.int32)
    for rows in (pn[:1], pn):
        np.testing.assert_array_equal(narrow_ws.novelty(rows, weights), wide_ws.novelty(rows, weights))
        as_bytes = weights.astype(np.uint8)
        np.testing.assert_array_equal(narrow_ws.novelty(rows, weights), narrow_ws.novelty(rows, as_bytes))
        np.testing.assert_array_equal(narrow_ws.active(rows), wide_ws.active(rows))


def test_compiled_eigh_of_the_compass_equals_numpys():
    from antarium.ant.cx_kernels import eigh3

    rng = np.random.default_rng(6)
    for scale in (1e-3, 1.0, 1e3):
        for _ in range(50):
            a = rng.normal(size=(3, 3)) * scale
            m = a @ a.T
            w, v = eigh3(m)
            w_ref, v_ref = np.linalg.eigh(m)
            np.testing.assert_allclose(w, w_ref, rtol=1e-12, atol=1e-12 * scale * scale)
            for j in range(3):  # eigenvectors up to their sign
                assert abs(abs(v[:, j] @ v_ref[:, j]) - 1.0) < 1e-9


def test_cxmb_lays_out_the_mbons_and_clips_the_turn_as_numpy_does():
    from antarium.ant.central_complex import PREFS
    from antarium.ant.command import clip_turn as _clip
    from antarium.ant.navigation import _MBON_TO_CPU4, heading_bump

    m = np.random.default_rng(7).random(8)
    np.testing.assert_array_equal(m[_MBON_TO_CPU4], np.tile(np.roll(m, 4), 2))
    for x in (0.3, -0.7, 0.7, 0.5, -0.5, math.inf, -math.inf, np.float64(0.2), 1e-300):
        assert _clip(x, 0.5) == float(np.clip(x, -0.5, 0.5))
        assert type(_clip(x, 0.5)) is float
    assert math.isnan(_clip(math.nan, 0.5))
    for desired, height in ((0.3, 0.7), (-2.0, 1.0), (10.0, 0.0)):
        np.testing.assert_array_equal(heading_bump(desired, height),
                                      np.tile(0.5 + 0.5 * height * np.cos(PREFS - (desired + math.pi)), 2))


def test_kcs_read_any_number_of_mbons_in_turn_and_refuse_another_layers():
    from antarium.ant.mushroom_body import MBON, KenyonCells

    rng = np.random.default_rng(8)
    kc = KenyonCells(200, 1000, 10, 0.02, seed=9)
    mbons = [MBON(1000) for _ in range(3)]
    for j, mbon in enumerate(mbons):
        mbon.learn(kc.active(rng.random((j + 2, 200), dtype=np.float32)))
    pn = rng.random((4, 200), dtype=np.float32)
    active = kc.active(pn)
    for group in (mbons, mbons[1:2], mbons, mbons[::-1]):  # the table the kernel reads is reused, resized
        expected = np.stack([m.novelty(active) for m in group], axis=1)
        np.testing.assert_array_equal(kc.novelty(pn, group), expected)
    with pytest.raises(ValueError, match="an MBON of 999 KCs cannot read a layer of 1000 KCs"):
        kc.novelty(pn, [mbons[0], MBON(999)])
