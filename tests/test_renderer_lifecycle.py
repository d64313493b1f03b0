"""A Renderer's life: a refused construction keeps no GL context, a released renderer refuses work in one line, a
scene without a far-field table frees the GPU path's copy of the last one, every face size samples coarser mipmap
levels for a low-pass, and a drifting far field finer than its per-frame texture carries is refused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from _moderngl import InvalidObject

import antarium.renderers.renderer as renderer_module
from antarium.core.pose import Pose
from antarium.renderers import shaders
from antarium.renderers.library import build_scene
from antarium.renderers.renderer import Renderer, mip_face_size
from antarium.renderers.scene import MeshData, Scene, SceneObject

POSE = Pose(0.0, 0.0, 0.02, 0.3)


@pytest.fixture
def contexts(monkeypatch) -> list:
    """Every GL context a Renderer creates from now on (the real ones, recorded)."""
    made = []

    def create_context():
        ctx = real()
        made.append(ctx)
        return ctx

    real = renderer_module.create_context
    monkeypatch.setattr(renderer_module, "create_context", create_context)
    return made


def _live(contexts: list) -> int:
    return sum(not isinstance(ctx.mglo, InvalidObject) for ctx in contexts)


@pytest.mark.parametrize("bad", [{"face_size": 10}, {"near_radius": -1.0}, {"far_layer_error_deg": 9.0},
                                 {"footprint_deg": 0.0}, {"near": 2.0, "far": 1.0}, {"lod_texels": -1.0},
                                 {"layer_face_size": 4}])
@pytest.mark.parametrize("choice", [{"path": None}, {"far_layer": "auto"}])
def test_a_refused_renderer_leaves_no_gl_context(dome, contexts, bad, choice):
    with pytest.raises(ValueError):
        Renderer(dome, **choice, **bad)
    assert _live(contexts) == 0


def test_a_renderer_failing_after_its_context_was_made_releases_it(dome, contexts, monkeypatch):
    monkeypatch.setattr(shaders, "BACKGROUND_FS", "#version 330\nnot a shader")
    with pytest.raises(Exception, match="(?i)error"):
        Renderer(dome, face_size=64)
    assert len(contexts) == 1 and _live(contexts) == 0


def test_a_released_renderer_releases_once_and_refuses_work_in_one_line(dome):
    r = Renderer(dome, face_size=64, path="gpu")
    r.set_scene("sky")
    r.render(POSE, t=0)
    r.release()
    r.release()
    for call in (lambda: r.render(POSE, t=0), lambda: r.set_scene("sky"), lambda: r.cube_map(POSE, t=0)):
        with pytest.raises(RuntimeError, match=r"^renderer was released$"):
            call()


def test_a_scene_without_a_far_field_table_frees_the_gpu_copy_of_the_last_one(dome):
    r = Renderer(dome, face_size=64, path="gpu")
    try:
        r.set_scene("sky")
        r.render(POSE, t=0)
        with_table, table_bytes = r._gpu.gpu_bytes, r._gpu._table.size + r._gpu._cells.size
        grating = build_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": 30, "colour": [0.5, 0.3, 0.2]})
        r.set_scene(Scene(far=build_scene("sky").far + grating.far, name="two rates"))  # two yaw rates: no table
        assert r._table is None
        r.render(POSE, t=0)
        assert r._gpu._table_source is None
        matrix_bytes = sum(b.size for b in r._gpu._matrix)  # uploaded for this scene's first frame
        assert r._gpu.gpu_bytes == with_table - table_bytes + matrix_bytes
        r.set_scene("sky")  # and a table again: uploaded by the first frame
        assert r.render(POSE, t=0).max() > 1000
        assert r._gpu.gpu_bytes == with_table + matrix_bytes
    finally:
        r.release()


def test_every_requested_face_size_becomes_one_whose_mipmap_levels_halve_it():
    for n in range(16, 2049):
        m = mip_face_size(n)
        k = max(0, m.bit_length() - 5)  # m >> k has 5 binary digits: 16..31
        assert m >= n and m % (1 << k) == 0, n
        assert all(mip_face_size(j) != j for j in range(n, m)), n  # the next such size, none skipped
    assert [mip_face_size(n) for n in (16, 31, 55, 150, 192, 2047, 2048)] == [16, 31, 56, 152, 192, 2048, 2048]


def test_the_smallest_face_samples_a_coarser_mipmap_level_on_both_paths(dome):
    """Face 55 (the smallest for the 1.5 degree footprint) became 56: a low-pass samples mipmap level 1, as on an
    even face; an odd face sampled level 0 only (2,662 weights per LED at the widest low-pass); both paths agree."""
    import trimesh

    box = trimesh.creation.box(extents=(0.5, 0.5, 0.5))
    v = np.asarray(box.vertices) + [0, 0, 0.25]
    mesh = MeshData(v.astype(np.float32), np.asarray(box.faces), np.tile((0.8, 0.1, 0.3), (len(v), 1)))
    frames = []
    for path in ("cpu", "gpu"):
        r = Renderer(dome, face_size=55, path=path)
        try:
            assert r.face_size == 56
            scene = build_scene({"scene": "horizon", "sky": 0.45, "ground": 0.2, "lowpass_deg": 30})
            scene.objects["box"] = SceneObject(mesh, position=(1.0, 0.5, 0.0))
            scene.__post_init__()
            r.set_scene(scene)
            frames.append(r.render(POSE, t=0).astype(np.int64))
            assert r._sampling()[0] == 1
        finally:
            r.release()
    assert frames[0].max() > 1000
    assert np.abs(frames[0] - frames[1]).max() <= 1


def test_a_drifting_grating_finer_than_the_far_texture_carries_is_refused(dome):
    r = Renderer(dome, face_size=64, path="cpu")
    try:
        smallest = r.smallest_drift_period_deg()
        assert smallest == pytest.approx(7 * math.degrees(2 * math.atan(1 / 64)))
        r.set_scene("sky")
        fine = {"scene": "grating", "period_deg": 1, "orientation_deg": 90, "speed_deg_s": 10, "colour": [1, 0, 0]}
        with pytest.raises(ValueError, match=rf"period must be at least {smallest:.2f} deg .*got 1 deg$"):
            r.set_scene(fine)
        assert r.scene.name == "sky"
        for refused in (lambda: r.set_far(build_scene(fine).far), lambda: r.prepare_scene(fine)):
            with pytest.raises(ValueError, match="period must be at least"):
                refused()
        assert r.set_scene({**fine, "speed_deg_s": 0}).name == "grating"  # standing still: the table, any period
    finally:
        r.release()


def test_a_drifting_grating_at_the_smallest_period_shows_what_it_shows_standing_still(dome):
    """At the smallest period accepted, each LED of the grating drifting (the far texture redrawn every frame at one
    sample a texel) is within 0.02 of the same phase standing still (drawn from the supersampled texture)."""
    drifting = Renderer(dome, face_size=64, path="cpu")
    still = Renderer(dome, face_size=64, path="cpu", fast_far_field=False)
    try:
        period = math.ceil(drifting.smallest_drift_period_deg() * 10) / 10
        base = {"scene": "grating", "period_deg": period, "orientation_deg": 90, "colour": [1, 0, 0]}
        drifting.set_scene({**base, "speed_deg_s": 10})
        gb = ~dome.is_uv
        for t in (0.13, 0.77):
            still.set_scene({**base, "phase_deg": (-360.0 * 10 * t / period) % 360.0})
            a = drifting.render(POSE, t=t)[gb, 0] / (65535.0 * dome.gain[gb])
            b = still.render(POSE, t=0)[gb, 0] / (65535.0 * dome.gain[gb])
            assert b.max() - b.min() > 0.3, "a uniform field proves nothing"
            assert np.abs(a - b).max() < 0.02
    finally:
        drifting.release()
        still.release()
