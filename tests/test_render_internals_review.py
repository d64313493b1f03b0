"""Review of the renderer's internals (session 19): a UV channel gain above 1 keeps the sky's degree of polarisation
on both paths, unusual constructor arguments are refused before the GL context is made, and the GPU path matches the
CPU path at the smallest face and at extreme headings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.geometry import load_dome
from antarium.renderers.output import FrameConverter
from antarium.renderers.renderer import Renderer
from antarium.renderers.sky import degree_of_polarisation, sun_direction


@pytest.fixture(scope="module")
def dome():
    return load_dome()


def test_a_saturated_uv_pixel_is_scaled_as_a_whole_by_the_converter(dome):
    conv = FrameConverter(np.ones(len(dome.directions)), 1.0)
    conv.configure(channel_gain=(1.0, 1.0, 2.0))
    pairs = np.zeros((len(dome.directions), 2), np.float32)
    pairs[dome.uv_index] = (0.8, 0.6)  # UV 0.8, polarised 0.6: degree 0.75; at gain 2 the UV is 1.6 of full drive
    out = conv(pairs, np.empty((len(pairs), 2), np.uint16)).astype(np.int64)
    plain, polarised = out[dome.uv_index, 0], out[dome.uv_index, 1]
    assert np.all(plain + polarised >= 65534) and np.all(plain + polarised <= 65535)
    assert np.abs(polarised / (plain + polarised) - 0.75).max() < 1e-4


@pytest.mark.parametrize("path", ["cpu", "gpu"])
def test_a_uv_channel_gain_above_one_keeps_the_skys_degree_of_polarisation(dome, path):
    r = Renderer(dome, face_size=56, path=path)
    try:
        r.set_scene({"scene": "sky", "sun_azimuth_deg": 0, "sun_elevation_deg": 30, "dop_max": 0.75})
        r.scale_channel("uv", 4.0)
        frame = r.render(Pose(0.0, 0.0, 0.01, 0.0)).astype(np.float64)
    finally:
        r.release()
    uv = dome.uv_index
    total = frame[uv, 0] + frame[uv, 1]
    up = dome.elevation[uv] > math.radians(10)
    assert np.all(total[up] >= 65534)  # every UV pixel of the sky saturates at gain 4
    expect = degree_of_polarisation(dome.directions[uv], sun_direction(0.0, math.radians(30)), 0.75)
    # before: the UV clipped alone, the polarised share not: degrees up to 0.69 above Rayleigh's
    assert np.abs(frame[uv, 1] / total - expect)[up].max() < 0.01


@pytest.mark.parametrize("kwargs, words", [
    ({"far_face_size": -5}, "far_face_size must be an integer in 16..2048"),
    ({"far_face_size": 100_000}, "far_face_size must be an integer in 16..2048"),
    ({"far_face_size": 1.5}, "far_face_size must be an integer in 16..2048"),
    ({"chunk_size": 0.0}, "chunk_size must be a positive number of metres"),
    ({"chunk_size": float("nan")}, "chunk_size must be a positive number of metres"),
    ({"far_layer_error_deg": "0.5"}, "far_layer_error_deg must be in (0, 5]"),
    ({"lod_texels": None}, "lod_texels must be a non-negative number"),
    ({"near": "0.001"}, "clip planes must satisfy 0 < near < far"),
])
def test_unusual_constructor_arguments_are_refused_in_one_line(dome, kwargs, words, monkeypatch):
    import antarium.renderers.renderer as renderer_module

    def no_context():
        raise AssertionError("a GL context was made before the arguments were checked")

    monkeypatch.setattr(renderer_module, "create_context", no_context)
    with pytest.raises(ValueError) as err:
        Renderer(dome, face_size=64, path="cpu", **kwargs)
    assert words in str(err.value) and "\n" not in str(err.value)


def test_the_gpu_path_matches_the_cpu_path_at_the_smallest_face_and_extreme_headings(dome):
    cpu, gpu = Renderer(dome, face_size=55, path="cpu"), Renderer(dome, face_size=55, path="gpu")
    try:
        assert cpu.face_size == gpu.face_size == 56
        poses = [Pose(0.0, 0.0, 0.01, 1e6), Pose(9.99, -9.99, 0.01, -12345.678), Pose(0.0, 0.0, 50.0, math.pi / 4)]
        for spec in ({"scene": "checkerboard", "size_deg": 5},  # far field only: the table on the GPU
                     {"scene": "grating", "orientation_deg": 90, "period_deg": 20, "speed_deg_s": 20}):  # atlas
            cpu.set_scene(spec)
            gpu.set_scene(spec)
            for pose in poses:
                a = cpu.render(pose, t=0.3).astype(np.int64)
                b = gpu.render(pose, t=0.3).astype(np.int64)
                assert np.abs(a - b).max() <= 1, (spec["scene"], pose)
    finally:
        cpu.release()
        gpu.release()
