"""Limits the renderer states once and keeps: the widest low-pass and the smallest face size derive from the
footprint (refused up front, in one line, instead of failing in a later frame), and a sun brighter than 1 gives
the same LEDs on the far-field table and on the GL background pass (and on the GPU path)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.config import ConfigError, resolve
from antarium.core.pose import Pose
from antarium.geometry import load_dome
from antarium.renderers import footprint
from antarium.renderers.renderer import MAX_FACE_SIZE, Renderer, smallest_face_size
from antarium.server.config_check import check_config, face_size_range

DRIFT = {"scene": "grating", "orientation_deg": 90, "speed_deg_s": 10}  # time-varying: the footprint matrix
POSE = Pose(0.0, 0.0, 0.1, 0.0)


@pytest.fixture(scope="module")
def dome():
    return load_dome()


@pytest.fixture(scope="module")
def small(dome):
    r = Renderer(dome, face_size=64, path="cpu")
    yield r
    r.release()


# ------------------------------------------------------------------------------------------------ low-pass
def test_the_widest_lowpass_derives_from_the_widest_footprint():
    for fp in (footprint.LED_PITCH_DEG, 13.0):
        widest = footprint.max_lowpass_deg(fp)
        assert math.degrees(footprint.footprint_fwhm(fp, widest)) < footprint.MAX_FWHM_DEG
        assert math.degrees(footprint.footprint_fwhm(fp, widest + 0.1)) >= footprint.MAX_FWHM_DEG
    assert footprint.max_lowpass_deg() == 101.9


def test_a_lowpass_too_wide_is_refused_up_front_and_the_previous_one_stays(small):
    small.set_scene({**DRIFT, "lowpass_deg": 10})
    small.render(POSE, t=1)
    fwhm = small.footprint_fwhm
    with pytest.raises(ValueError, match=r"lowpass_deg .* <= 101\.9, got 120"):
        small.set_lowpass(120.0)
    assert small.scene.lowpass_deg == 10 and small.footprint_fwhm == fwhm
    assert small.render(POSE, t=1).max() > 0


def test_a_scene_with_a_lowpass_too_wide_is_refused_and_the_previous_scene_stays(small):
    small.set_scene(DRIFT)
    for spec in ({**DRIFT, "lowpass_deg": 150}, {"scene": "sky", "lowpass_deg": 150}):
        with pytest.raises(ValueError, match=r"<= 101\.9, got 150"):
            small.set_scene(spec)
        assert small.scene.lowpass_deg is None and small.scene.far[0].time_varying
    small.render(POSE, t=1)


def test_the_widest_lowpass_accepted_renders_a_time_varying_scene(small):
    small.set_scene(DRIFT)
    small.set_lowpass(footprint.max_lowpass_deg(small.footprint_deg))
    assert small.render(POSE, t=1).max() > 0
    small.set_lowpass(None)


def test_a_renderer_with_a_wider_footprint_refuses_the_lowpass_its_footprint_cannot_take(dome):
    r = Renderer(dome, face_size=64, footprint_deg=13.0, path="cpu")
    try:
        r.set_scene(DRIFT)
        r.set_lowpass(footprint.max_lowpass_deg(13.0))  # 97.6
        r.render(POSE, t=1)
        with pytest.raises(ValueError, match=r"<= 97\.6, got 100"):
            r.set_lowpass(100.0)  # a scene alone (the LED pitch) would take it
        with pytest.raises(ValueError, match=r"<= 97\.6, got 100"):
            r.set_scene({**DRIFT, "lowpass_deg": 100.0})
        assert r.scene.lowpass_deg == 97.6
        r.render(POSE, t=1)
    finally:
        r.release()


# ------------------------------------------------------------------------------------------------ face size
def test_the_smallest_face_size_is_the_one_where_every_direction_sees_a_texel():
    n = footprint.min_face_size()
    assert n == smallest_face_size() == 55
    centres = np.eye(3)  # the farthest points from any texel centre, at an even face size
    fwhm = math.radians(footprint.LED_PITCH_DEG)
    footprint.build_matrix(centres, n, fwhm)
    with pytest.raises(ValueError, match="smaller than a texel"):
        footprint.build_matrix(centres, n - 1, fwhm)


def test_a_face_too_small_for_the_footprint_is_refused_at_construction(dome):
    n = smallest_face_size()
    for bad in (16, 32, n - 1):
        with pytest.raises(ValueError, match=rf"face_size must be an integer in {n}\.\.{MAX_FACE_SIZE} .*raise "
                                             rf"face_size\), got {bad}$"):
            Renderer(dome, face_size=bad, path="cpu")
    r = Renderer(dome, face_size=n, path="cpu")
    try:
        r.set_scene(DRIFT)
        assert r.render(POSE, t=1).max() > 0
    finally:
        r.release()
    wide = Renderer(dome, face_size=16, footprint_deg=13.0, path="cpu")  # a wide footprint needs fewer texels
    wide.release()


def test_the_config_allows_the_face_sizes_the_renderer_takes():
    assert face_size_range() == (smallest_face_size(), MAX_FACE_SIZE)
    base = {"bus": {"enabled": False}, "link": {"interface": "virtual"}}
    with pytest.raises(ConfigError, match=r"face_size_px = 54 is .* allowed: 55\.\.2048 texels"):
        check_config(resolve({**base, "render": {"scene": "uniform", "face_size_px": 54}}))
    check_config(resolve({**base, "render": {"scene": "uniform", "face_size_px": 55}}))


# ------------------------------------------------------------------------------------------------ bright sun
SUN = {"scene": "sky", "sun_azimuth_deg": 30, "sun_elevation_deg": 40, "zenith": 0.02}


@pytest.fixture(scope="module")
def paths(dome):
    """The far-field table (CPU), and the GL background pass on the CPU and on the GPU path (llvmpipe here)."""
    rs = (Renderer(dome, face_size=96, path="cpu"), Renderer(dome, face_size=96, path="cpu", fast_far_field=False),
          Renderer(dome, face_size=96, path="gpu", fast_far_field=False))
    yield rs
    for r in rs:
        r.release()


def _frames(paths, spec) -> list[np.ndarray]:
    out = []
    for r in paths:
        r.set_scene(spec)
        out.append(r.render(POSE, t=0).astype(np.int64))
    return out


def test_a_sun_brighter_than_1_lights_the_same_leds_on_every_path(paths, dome):
    """Within the sun's reach (its radius plus the footprint's, one FWHM) every path saturates the same LEDs
    (within 1 LSB, the CPU-vs-GPU tolerance); beyond it no path shows more of the sun than at radiance 1 (1 LSB). In
    the 0.4 degree ring between, the paths discretise the disc's edge differently (one LED here)."""
    sun = np.array([math.cos(math.radians(40)) * math.cos(math.radians(30)),
                    math.cos(math.radians(40)) * math.sin(math.radians(30)), math.sin(math.radians(40))])
    angle = np.degrees(np.arccos(np.clip(dome.directions @ sun, -1, 1)))
    reach = 0.75 + footprint.LED_PITCH_DEG  # sun_radius_deg + the footprint's radius
    near, far = angle < reach - 0.15, angle > reach + 0.25
    assert near.sum() >= 8
    table, gl, gpu = _frames(paths, {**SUN, "sun_radiance": 1000})
    assert table[near].min() > 30000  # the table lit them
    for other in (gl, gpu):
        assert np.abs(other[near] - table[near]).max() <= 1
    dim = _frames(paths, {**SUN, "sun_radiance": 1})
    for bright, plain in zip((table, gl, gpu), dim, strict=True):
        assert np.abs(bright[far] - plain[far]).max() <= 1


@pytest.mark.parametrize("spec", [{**SUN, "sun_radiance": 1000, "lowpass_deg": 20},
                                  {"scene": "sky", "sun_radiance": 50, "sun_elevation_deg": 60, "contrast": 2.0,
                                   "channel_gain": [1, 3, 2]}])
def test_the_gpu_path_matches_the_cpu_path_on_a_sun_brighter_than_1(paths, spec):
    _, cpu, gpu = paths
    for pose in (POSE, Pose(0.3, -0.2, 0.1, 2.5)):
        for r in (cpu, gpu):
            r.set_scene(spec)
        a, b = (r.render(pose, t=0).astype(np.int64) for r in (cpu, gpu))
        assert a.max() > 30000 and np.abs(a - b).max() <= 1
