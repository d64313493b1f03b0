"""Renderer correctness against the geometry and numpy references (real EGL context, llvmpipe here)."""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers import cubemap, footprint
from antarium.renderers.library import build_scene
from antarium.renderers.renderer import Renderer
from antarium.renderers.stimuli import Bar

FACE = 128  # smaller than the default to keep tests quick; the maths does not depend on the size
FWHM = math.radians(1.5)


@pytest.fixture(scope="module")
def renderer(dome):
    """Every scene through GL (the far-field fast path is compared against it separately)."""
    r = Renderer(dome, face_size=FACE, fast_far_field=False)
    yield r
    r.release()


@pytest.fixture(scope="module")
def fast(dome):
    """The default configuration: scenes without meshes take the far-field table."""
    r = Renderer(dome, face_size=FACE)
    yield r
    r.release()


def radiance(frame: np.ndarray, dome) -> np.ndarray:
    """Undo gain: (20350, 2) drive -> linear radiance per LED column, in [0, 1]."""
    return frame.astype(np.float64) / (65535.0 * dome.gain[:, None])


def test_single_bar_lights_exactly_the_leds_it_covers(renderer, dome):
    renderer.set_scene({"scene": "bars", "azimuth_deg": 30, "width_deg": 10, "colour": [1, 0, 0],
                        "background": 0.0})
    frame = renderer.render(Pose(0, 0, 0.01, 0.0))
    green = radiance(frame, dome)[~dome.is_uv, 0]
    d = dome.directions[~dome.is_uv]
    az = dome.azimuth[~dome.is_uv]
    # angular distance to the two meridian planes bounding the bar
    edges = np.radians([25.0, 35.0])
    normals = np.stack([-np.sin(edges), np.cos(edges), np.zeros(2)], axis=1)
    dist = np.degrees(np.arcsin(np.abs(d @ normals.T))).min(axis=1)
    inside = Bar(azimuth=math.radians(30), width=math.radians(10)).covers(d)
    front = np.cos(az - math.radians(30)) > 0
    radius = 1.5 + cubemap.largest_texel_deg(FACE)  # footprint + the far texture's bilinear filter
    assert np.all(green[inside & (dist > radius)] > 0.99)
    assert np.all(green[~inside & (dist > radius)] < 1e-3)
    ok = front & (dist > 0.3)
    assert np.array_equal(green[ok] > 0.5, inside[ok])
    assert inside.sum() > 300


def test_rotating_the_scene_by_90_deg_permutes_leds_as_the_geometry_predicts(renderer, dome):
    # a seamless drum of 9 periods: a 90 deg rotation shifts its phase by a quarter period
    renderer.set_scene({"scene": "grating", "period_deg": 40, "contrast": 0.8, "colour": [1, 0, 0]})
    before = radiance(renderer.render(Pose(0, 0, 0.01, 0.0)), dome)[:, 0].copy()
    renderer.rotate_scene(math.radians(90))
    after = radiance(renderer.render(Pose(0, 0, 0.01, 0.0)), dome)[:, 0]
    # what LED i shows now, LED j showed before where d_j = Rz(-90) d_i
    c, s = 0.0, -1.0
    source = dome.directions @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T
    from scipy.spatial import cKDTree

    dist, j = cKDTree(dome.directions).query(source)
    # below 60 deg elevation the drum's local period stays >= 20 deg, so a 0.25 deg offset changes little
    close = (np.degrees(dist) < 0.25) & ~dome.is_uv & ~dome.is_uv[j] & (np.abs(dome.elevation) < np.radians(60))
    assert close.sum() > 1000
    err = np.abs(after[close] - before[j[close]])
    assert err.max() < 0.04 and err.mean() < 0.008


def test_gl_output_matches_the_numpy_reference(renderer, dome):
    scene = build_scene({"scene": "checkerboard", "size_deg": 20, "colour_a": [0.1, 0.6, 0.3],
                         "colour_b": [0.7, 0.2, 0.6]})  # G + B < 1: no cap
    renderer.set_scene(scene)
    frame = renderer.render(Pose(0, 0, 0.01, math.radians(17)))
    atlas = renderer.cube_map(Pose(0, 0, 0.01, math.radians(17))).reshape(-1, 4)
    pick = np.random.default_rng(1).choice(np.flatnonzero(~dome.is_uv), 400, replace=False)
    # (1) sparse-matrix sampling == brute-force footprint integral of the same cube map
    ref = footprint.reference_sample(atlas, dome.directions[pick], FWHM)
    got = radiance(frame, dome)[pick]
    assert np.abs(got - ref[:, :2]).max() < 2e-3
    # (3) end to end: LEDs == numpy far field integrated over each LED's footprint
    q = renderer.view_rotation(Pose(0, 0, 0.01, math.radians(17)))
    expect = scene.evaluate_far(cubemap.atlas_directions(FACE) @ q.T)[:, :3]
    ref_np = footprint.reference_sample(expect, dome.directions[pick], FWHM)
    assert np.abs(got - ref_np[:, :2]).mean() < 0.015  # the far texture adds its bilinear filter


def test_gl_cube_map_matches_the_far_field_in_numpy(renderer):
    scene = build_scene({"scene": "sky", "sun_azimuth_deg": 60, "sun_elevation_deg": 35})
    renderer.set_scene(scene)
    pose = Pose(0, 0, 0.01, math.radians(-40))
    atlas = renderer.cube_map(pose).reshape(-1, 4)
    world = cubemap.atlas_directions(FACE) @ renderer.view_rotation(pose).T
    expect = scene.evaluate_far(world)
    agree = np.isclose(atlas, expect, atol=0.01).all(axis=1)
    assert agree.mean() > 0.99  # the rest: the horizon line and the sun's disc, blended by the texture filter


def test_uv_pixels_carry_the_skys_degree_of_polarisation(renderer, dome):
    from antarium.renderers.sky import degree_of_polarisation, sun_direction

    renderer.set_scene({"scene": "sky", "sun_azimuth_deg": 0, "sun_elevation_deg": 60, "dop_max": 0.7})
    frame = renderer.render(Pose(0, 0, 0.01, 0.0)).astype(np.float64)
    uv = dome.uv_index
    up = dome.elevation[uv] > math.radians(5)
    total = frame[uv, 0] + frame[uv, 1]
    dop = frame[uv, 1] / total
    expect = degree_of_polarisation(dome.directions[uv], sun_direction(0.0, math.radians(60)), 0.7)
    far_from_sun = np.degrees(np.arccos(dome.directions[uv] @ sun_direction(0.0, math.radians(60)))) > 5
    sel = up & far_from_sun
    assert sel.sum() > 200
    assert np.abs(dop[sel] - expect[sel]).max() < 0.03


def test_polariser_angles_reproduce_the_skys_e_vectors(renderer, dome):
    from antarium.renderers.sky import e_vector

    renderer.set_scene({"scene": "sky", "sun_azimuth_deg": 40, "sun_elevation_deg": 30})
    heading = math.radians(25)
    renderer.render(Pose(0, 0, 0.01, heading))
    psi = renderer.polariser_angles()
    assert psi.shape == (55, 9) and np.all((psi >= 0) & (psi < np.pi))
    uv = dome.uv_index
    d = dome.directions[uv]
    axes = dome.panel_axes[dome.panel[uv]]
    p = psi.ravel()
    u = np.cos(p)[:, None] * axes[:, 0] + np.sin(p)[:, None] * axes[:, 1]
    u_perp = u - np.einsum("ij,ij->i", u, d)[:, None] * d  # what leaves the polariser along -d
    u_perp /= np.linalg.norm(u_perp, axis=1, keepdims=True)
    q = renderer.view_rotation(Pose(0, 0, 0.01, heading))
    e = e_vector(d @ q.T, renderer.scene.sky.sun) @ q
    ok = np.linalg.norm(e, axis=1) > 0.5
    assert np.all(np.abs(np.einsum("ij,ij->i", u_perp[ok], e[ok])) > 0.999)


def test_frame_contract(renderer, dome):
    renderer.set_scene("habitat")
    out = np.zeros((20350, 2), np.uint16)
    res = renderer.render(Pose(0.3, -0.2, 0.01, 1.0), out=out)
    assert res is out and out.dtype == np.uint16
    assert np.all(out.astype(np.int64).sum(axis=1) <= 65535)
    assert out[~dome.is_uv].max() > 0
    assert set(renderer.last_timings) == {"render", "sample", "convert"}


def test_failed_scene_load_keeps_the_previous_scene(renderer, tmp_path):
    renderer.set_scene({"scene": "grating", "period_deg": 30})
    before = renderer.render(Pose(0, 0, 0.01, 0.0)).copy()
    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"glTF not really")
    for spec in (str(tmp_path / "missing.obj"), str(bad), {"scene": "grating", "period_deg": -5},
                 {"scene": "nonsense"}, str(tmp_path / "x.xyz")):
        with pytest.raises((ValueError, FileNotFoundError)):
            renderer.set_scene(spec)
        assert np.array_equal(renderer.render(Pose(0, 0, 0.01, 0.0)), before)


@pytest.mark.parametrize("t", [math.nan, math.inf])
def test_a_time_that_is_not_finite_is_refused(renderer, t):
    renderer.set_scene("sky")
    for draw in (renderer.render, renderer.cube_map):
        with pytest.raises(ValueError) as err:
            draw(Pose(0, 0, 0.01, 0.0), t=t)
        assert str(err.value) == f"time t (s) must be a finite number, got {t!r}"


@pytest.mark.parametrize("bad", [(0, 0, math.nan, 0), (0, math.inf, 0, 0), (0, 0, 0), "pose"])
def test_bad_pose_is_refused(renderer, bad):
    renderer.set_scene("uniform")
    with pytest.raises(ValueError, match="pose"):
        renderer.render(bad)


@pytest.mark.parametrize("spec", [
    {"scene": "sky", "sun_azimuth_deg": 200, "sun_elevation_deg": 50},
    {"scene": "grating", "period_deg": 30, "orientation_deg": 90, "colour": [0.5, 0.3, 0.2]},
    {"scene": "bars", "bars": [{"azimuth_deg": -60, "width_deg": 8}, {"azimuth_deg": 100, "width_deg": 20,
                                                                       "top_deg": 30}], "colour": 0.4},
])
def test_far_field_fast_path_matches_the_gl_path(renderer, fast, dome, spec):
    pose = Pose(1.0, 2.0, 0.01, math.radians(33))
    renderer.set_scene(spec)
    gl = radiance(renderer.render(pose), dome)
    fast.set_scene(spec)
    assert fast._table is not None
    quick = radiance(fast.render(pose), dome)
    err = np.abs(quick - gl)
    assert err.mean() < 0.003 and np.percentile(err, 99) < 0.03


def test_lowpass_in_the_gl_path_matches_the_far_field_table(renderer, fast, dome):
    """A wide low-pass samples a coarser mipmap level of the atlas; it must agree with the exact table."""
    spec = {"scene": "grating", "period_deg": 40, "contrast": 0.8, "colour": [1, 0, 0], "lowpass_deg": 30}
    pose = Pose(0, 0, 0.01, math.radians(10))
    renderer.set_scene(spec)
    gl = radiance(renderer.render(pose), dome)
    assert renderer._sampling()[0] == 2  # 128 -> 32 texels per face for a 13 deg footprint
    fast.set_scene(spec)
    quick = radiance(fast.render(pose), dome)
    band = (np.abs(dome.elevation) < math.radians(50)) & ~dome.is_uv
    # a 40 deg period keeps exp(-2 pi^2 sigma^2 / 40^2) = 0.68 of its amplitude under a 30 deg cut-off
    assert np.ptp(gl[band, 0]) == pytest.approx(0.68 * 0.8, abs=0.05)
    assert np.abs(gl[band] - quick[band]).mean() < 0.01


def test_rayleigh_sky_formula_at_known_points():
    from antarium.renderers.sky import degree_of_polarisation, e_vector, sun_direction

    zenith_sun = sun_direction(0.0, math.pi / 2)
    s45 = math.sqrt(0.5)
    d = np.array([[1.0, 0, 0], [s45, 0, s45], [0, 0, 1.0], [0, 0, -1.0]])
    dop = degree_of_polarisation(d, zenith_sun, 0.75)
    # gamma = 90, 45, 0, 180 deg: dop_max sin^2 / (1 + cos^2) = 0.75, 0.75 / 3, 0, 0
    assert np.allclose(dop, [0.75, 0.25, 0.0, 0.0])
    e = e_vector(d, zenith_sun)
    assert np.allclose(e[0], [0, 1, 0])  # looking at the horizon under a zenith sun: horizontal e-vector
    assert np.allclose(e[2:], 0)  # no e-vector towards or away from the sun
    # sun on the horizon at azimuth 0, looking at the zenith: e-vector perpendicular to the solar meridian
    assert np.allclose(np.abs(e_vector(np.array([[0, 0, 1.0]]), sun_direction(0.0, 0.0))), [[0, 1, 0]])


def test_missing_egl_names_the_system_packages(monkeypatch):
    import moderngl

    from antarium.renderers import gl

    def no_egl(**kwargs):
        raise Exception("libEGL.so.1: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_context", no_egl)
    with pytest.raises(RuntimeError, match="libegl1.*libgl1-mesa-dri"):
        gl.create_context()


def test_two_renderers_in_one_thread_each_draw_their_own_scene(dome):
    """Each renderer makes its own GL context current: interleaved use gives what each gives alone."""
    pose = Pose(0.3, -0.2, 0.01, 0.4)
    alone = []
    for face in (128, 96):
        r = Renderer(dome, face_size=face)
        r.set_scene("habitat")
        alone.append(r.render(pose, t=0.0).copy())
        r.release()
    a, b = Renderer(dome, face_size=128), Renderer(dome, face_size=96)  # b's context is the newest
    try:
        a.set_scene("habitat")
        b.set_scene("habitat")
        for _ in range(2):
            np.testing.assert_array_equal(a.render(pose, t=0.0), alone[0])
            np.testing.assert_array_equal(b.render(pose, t=0.0), alone[1])
    finally:
        a.release()
        b.release()


def test_the_python_block_of_docs_rendering_runs_as_written():
    """docs/rendering.md's Python block, run as written: one frame of the habitat, into the buffer it makes."""
    text = (Path(__file__).resolve().parent.parent / "docs" / "rendering.md").read_text()
    block = re.search(r"```python\n(.*?)```", text, re.S)
    assert block, "docs/rendering.md: no python block"
    namespace = {}
    exec(block.group(1), namespace)  # noqa: S102 - the doc's own code
    renderer = namespace["renderer"]
    try:
        frame = namespace["frame"]
        assert frame is namespace["frame_buffer"] and frame.shape == (20350, 2) and frame.dtype == np.uint16
        assert frame.any() and namespace["angles"].shape == (55, 9)
        assert {"render", "sample", "convert"} <= set(renderer.last_timings)
    finally:
        renderer.release()
