"""Scene loading (meshes, panoramas, the habitat), scene edits and bad input, with the real EGL renderer."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.library import build_scene
from antarium.renderers.renderer import Renderer
from antarium.renderers.scene import MeshData, SceneObject
from antarium.renderers.stimuli import Uniform

FACE = 96
HOME = Pose(0.0, 0.0, 0.01, 0.0)


def box(size=0.5, colour=(0.8, 0.1, 0.0)) -> MeshData:
    """A closed cube of side `size` (m) standing on z = 0, wound counter-clockwise seen from outside."""
    import trimesh

    m = trimesh.creation.box(extents=(size, size, size))
    v = np.asarray(m.vertices) + [0, 0, size / 2]
    return MeshData(v.astype(np.float32), np.asarray(m.faces), np.tile(colour, (len(v), 1)), double_sided=False)


def green(frame, dome):
    return frame[~dome.is_uv, 0].astype(np.float64) / (65535 * dome.gain[~dome.is_uv])


def lit_azimuth_deg(frame, dome, threshold=0.4) -> float:
    """Circular mean azimuth (deg) of the GB LEDs whose green radiance exceeds `threshold`."""
    g = green(frame, dome)
    az = dome.azimuth[~dome.is_uv][g > threshold]
    return math.degrees(math.atan2(np.sin(az).mean(), np.cos(az).mean()))


def box_world(renderer, position=(2.0, 0.0, 0.0)):
    scene = build_scene({"scene": "horizon", "sky": 0.0, "ground": 0.0})
    scene.objects["box"] = SceneObject(box(), position=position)
    scene.__post_init__()
    renderer.set_scene(scene)
    return scene


def test_mesh_object_appears_where_it_stands(renderer, dome):
    box_world(renderer, (2.0, 2.0, 0.0))
    assert lit_azimuth_deg(renderer.render(Pose(0, 0, 0.25, 0.0)), dome) == pytest.approx(45, abs=2)
    # turning the ant by +30 deg moves the world by -30 deg on the dome
    assert lit_azimuth_deg(renderer.render(Pose(0, 0, 0.25, math.radians(30))), dome) == pytest.approx(15, abs=2)


def test_move_remove_add_objects(renderer, dome):
    box_world(renderer)
    pose = Pose(0, 0, 0.25, 0.0)
    assert lit_azimuth_deg(renderer.render(pose), dome) == pytest.approx(0, abs=2)
    renderer.move_object("box", position=(0.0, -2.0, 0.0))
    assert lit_azimuth_deg(renderer.render(pose), dome) == pytest.approx(-90, abs=2)
    renderer.remove_object("box")
    assert green(renderer.render(pose), dome).max() < 1e-3
    renderer.add_object("tree", SceneObject(box(), position=(-2.0, 0.0, 0.0)))
    assert abs(lit_azimuth_deg(renderer.render(pose), dome)) == pytest.approx(180, abs=2)
    with pytest.raises(ValueError, match="no object named 'box'"):
        renderer.move_object("box", position=(1, 1, 0))
    with pytest.raises(ValueError, match="position"):
        renderer.move_object("tree", position=(1, math.nan, 0))
    assert abs(lit_azimuth_deg(renderer.render(pose), dome)) == pytest.approx(180, abs=2)


def test_scene_rotation_is_instant_and_about_the_vertical(renderer, dome):
    box_world(renderer)
    pose = Pose(0, 0, 0.25, 0.0)
    renderer.rotate_scene(math.radians(90))
    assert lit_azimuth_deg(renderer.render(pose), dome) == pytest.approx(90, abs=2)
    renderer.rotate_scene(math.radians(-90))
    assert lit_azimuth_deg(renderer.render(pose), dome) == pytest.approx(-90, abs=2)


def test_channel_edits(renderer, dome):
    renderer.set_scene({"scene": "uniform", "colour": [0.4, 0.2, 0.3]})
    base = renderer.render(HOME).astype(np.float64)
    gb, uv = ~dome.is_uv, dome.is_uv
    renderer.scale_channel("uv", 0.0)
    no_uv = renderer.render(HOME).astype(np.float64)
    assert no_uv[uv].max() == 0 and np.array_equal(no_uv[gb], base[gb])
    renderer.scale_channel("green", 0.5)
    half = renderer.render(HOME).astype(np.float64)
    assert np.allclose(half[gb, 0], base[gb, 0] / 2, atol=1) and np.array_equal(half[gb, 1], base[gb, 1])
    renderer.scale_channel("green", 1.0)
    renderer.swap_green_blue(True)
    swapped = renderer.render(HOME).astype(np.float64)
    assert np.allclose(swapped[gb, 0], base[gb, 1], atol=1) and np.allclose(swapped[gb, 1], base[gb, 0], atol=1)
    with pytest.raises(ValueError, match="unknown channel 'red'"):
        renderer.scale_channel("red", 1.0)


def test_contrast_and_lowpass(renderer, dome):
    renderer.set_scene({"scene": "grating", "period_deg": 10, "contrast": 0.8, "colour": [1, 0, 0]})
    pose = HOME
    band = np.abs(dome.elevation[~dome.is_uv]) < math.radians(20)
    full = green(renderer.render(pose), dome)[band]
    renderer.set_contrast(0.5)
    low_c = green(renderer.render(pose), dome)[band]
    assert low_c.std() == pytest.approx(0.5 * full.std(), rel=0.05)
    renderer.set_contrast(1.0)
    renderer.set_lowpass(20.0)  # periods shorter than 20 deg fall below half amplitude; 10 deg nearly vanish
    blurred = green(renderer.render(pose), dome)[band]
    assert blurred.std() < 0.1 * full.std()
    assert blurred.mean() == pytest.approx(full.mean(), abs=0.02)
    renderer.set_lowpass(None)
    assert green(renderer.render(pose), dome)[band].std() == pytest.approx(full.std(), rel=0.02)
    with pytest.raises(ValueError, match="low-pass"):
        renderer.set_lowpass(-3)
    with pytest.raises(ValueError, match="contrast"):
        renderer.set_contrast(math.inf)


def test_fine_texture_averages_out_instead_of_aliasing(renderer, dome):
    """A 0.5 deg grating (a third of the LED pitch) must show as nearly uniform grey, not as moire."""
    renderer.set_scene({"scene": "grating", "period_deg": 0.5, "contrast": 1.0, "mean": 0.5, "colour": [1, 0, 0],
                        "waveform": "square"})
    g = green(renderer.render(HOME), dome)
    band = np.abs(dome.elevation[~dome.is_uv]) < math.radians(30)
    assert g[band].mean() == pytest.approx(0.5, abs=0.03)
    assert g[band].std() < 0.05


def test_drifting_drum_moves_at_its_speed(renderer, dome):
    renderer.set_scene({"scene": "grating", "period_deg": 40, "speed_deg_s": 20, "colour": [1, 0, 0]})
    a = green(renderer.render(HOME, t=0.0), dome)
    b = green(renderer.render(Pose(0, 0, 0.01, math.radians(-20)), t=1.0), dome)
    assert np.abs(a - b).max() < 1e-3  # after 1 s the drum turned by 20 deg: same as the ant turning -20 deg


def test_oblique_drift_is_evaluated_per_frame(renderer, dome):
    renderer.set_scene({"scene": "grating", "period_deg": 30, "orientation_deg": 90, "speed_deg_s": 15,
                        "colour": [1, 0, 0]})
    a = green(renderer.render(HOME, t=0.0), dome)
    b = green(renderer.render(HOME, t=1.0), dome)
    assert np.abs(a - b).max() > 0.2


def test_mesh_formats_load(renderer, dome, tmp_path):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=2, radius=0.3)
    m.apply_translation([1.5, 0, 0.3])
    m.visual.vertex_colors = np.tile([200, 30, 30, 255], (len(m.vertices), 1))
    from antarium.renderers.meshes import GLTF_TO_WORLD

    for suffix in (".obj", ".ply", ".stl", ".glb"):
        path = tmp_path / f"ball{suffix}"
        # glTF is +y up by its specification; the other formats are taken as +z up
        (m.copy().apply_transform(GLTF_TO_WORLD.T) if suffix == ".glb" else m).export(path)
        scene = build_scene(str(path))
        assert scene.n_triangles == len(m.faces)
        scene.far = [Uniform(0.0)]  # dark surroundings instead of the default sky
        renderer.set_scene(scene)
        frame = renderer.render(Pose(0, 0, 0.3, 0.0))
        lit = green(frame, dome) > 0.05
        az = dome.azimuth[~dome.is_uv][lit]
        assert lit.sum() > 50 and np.abs(az).max() < math.radians(20), suffix


def test_gltf_colours_are_linear_and_other_formats_srgb(tmp_path):
    """glTF's vertex colours and base colour factor are linear (its specification); PLY and OBJ vertex colours
    sRGB. Before 2026-11-26 glTF colours were decoded as sRGB: a mid-grey 128 became 0.22 instead of 0.50."""
    import trimesh

    from antarium.renderers.channels import rgb_to_gbu, srgb_to_linear
    from antarium.renderers.meshes import load_mesh_objects

    level = 128 / 255
    m = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    m.visual.vertex_colors = np.tile([128, 128, 128, 255], (len(m.vertices), 1))
    plain = trimesh.creation.box(extents=(0.2, 0.2, 0.2))
    plain.visual = trimesh.visual.TextureVisuals(
        material=trimesh.visual.material.PBRMaterial(baseColorFactor=[128, 128, 128, 255]))
    expected = {".glb": level, ".ply": srgb_to_linear(np.array(level)), ".obj": srgb_to_linear(np.array(level))}
    for suffix, value in expected.items():
        m.export(tmp_path / f"box{suffix}")
        (obj,) = load_mesh_objects(tmp_path / f"box{suffix}").values()
        np.testing.assert_allclose(obj.mesh.colours, np.tile(rgb_to_gbu(np.full(3, value)), (len(obj.mesh.colours), 1)),
                                   atol=1e-6, err_msg=suffix)
    plain.export(tmp_path / "plain.glb")
    (obj,) = load_mesh_objects(tmp_path / "plain.glb").values()
    np.testing.assert_allclose(obj.mesh.colours[0], rgb_to_gbu(np.full(3, level)), atol=1e-6)


def test_a_textured_quad_draws_as_its_untextured_twin(renderer, tmp_path):
    """A white texture under glTF base colour factor 128 (linear 0.502) draws G, B, UV = 0.502, 0.502, 0.1255, as
    the factor alone does. Before 2026-11-27 the factor's and the texture's UV = 0.25 B multiplied (UV 0.031)."""
    import trimesh
    from PIL import Image

    from antarium.renderers.meshes import GLTF_TO_WORLD, load_mesh_objects

    quad = dict(vertices=[[-10, -10, 0], [10, -10, 0], [10, 10, 0], [-10, 10, 0]], faces=[[0, 1, 2], [0, 2, 3]])
    white = Image.fromarray(np.full((8, 8, 3), 255, np.uint8))
    for texture in (None, white):
        material = trimesh.visual.material.PBRMaterial(baseColorTexture=texture, baseColorFactor=[128, 128, 128, 255])
        m = trimesh.Trimesh(**quad, process=False, visual=trimesh.visual.TextureVisuals(
            uv=[[0, 0], [1, 0], [1, 1], [0, 1]], material=material))
        m.apply_transform(GLTF_TO_WORLD.T).export(tmp_path / "quad.glb")
        scene = build_scene("uniform")
        scene.far = [Uniform(0.0)]
        scene.objects = load_mesh_objects(tmp_path / "quad.glb")
        scene.__post_init__()
        renderer.set_scene(scene)
        px = renderer.cube_map(Pose(0, 0, 0.5, 0.0)).reshape(-1, 4)
        np.testing.assert_allclose(px[px[:, 0] > 0.1, :3].mean(0), [0.502, 0.502, 0.1255], atol=2e-3,
                                   err_msg=str(texture))


def test_ply_face_colours_stay_on_their_faces(tmp_path):
    """A black and a white face sharing an edge stay black and white; their shared vertices blended to G 0.212."""
    import trimesh

    from antarium.renderers.meshes import load_mesh_objects

    m = trimesh.Trimesh(vertices=[[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], faces=[[0, 1, 2], [0, 2, 3]],
                        face_colors=[[0, 0, 0, 255], [255, 255, 255, 255]], process=False)
    m.export(tmp_path / "faces.ply")
    (obj,) = load_mesh_objects(tmp_path / "faces.ply").values()
    assert obj.mesh.colours[obj.mesh.faces, 0].tolist() == [[0.0] * 3, [1.0] * 3]


def test_textured_mesh(renderer, dome, tmp_path):
    import trimesh
    from PIL import Image

    tex = np.zeros((64, 64, 3), np.uint8)
    tex[:, :32] = [255, 255, 0]  # left half bright green+red, right half black
    m = trimesh.creation.box(extents=(0.01, 2.0, 2.0))
    uv = np.stack([(m.vertices[:, 1] + 1) / 2, (m.vertices[:, 2] + 1) / 2], axis=1)
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(tex),
                                                   baseColorFactor=[255, 255, 255, 255])
    m.visual = trimesh.visual.TextureVisuals(uv=uv, material=material)
    m.apply_translation([2.0, 0, 0])
    from antarium.renderers.meshes import GLTF_TO_WORLD

    m.apply_transform(GLTF_TO_WORLD.T)  # glTF is +y up
    path = tmp_path / "wall.glb"
    m.export(path)
    scene = build_scene(str(path))
    scene.far = [Uniform(0.0)]
    renderer.set_scene(scene)
    g = green(renderer.render(Pose(0, 0, 0.0, 0.0)), dome)
    az = dome.azimuth[~dome.is_uv]
    el = dome.elevation[~dome.is_uv]
    centre = np.abs(el) < math.radians(15)
    # texture u grows with +y (to the left seen from the origin): the bright half is on the right (az < 0)
    assert g[centre & (az < -math.radians(5)) & (az > -math.radians(20))].mean() > 0.5
    assert g[centre & (az > math.radians(5)) & (az < math.radians(20))].mean() < 0.05


def test_bad_files_are_refused_with_their_name(renderer, tmp_path):
    renderer.set_scene("uniform")
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    nan = tmp_path / "nan.obj"
    nan.write_text("v 0 0 0\nv 1 0 nan\nv 0 1 0\nf 1 2 3\n")
    corrupt_png = tmp_path / "pano.png"
    corrupt_png.write_bytes(b"\x89PNG not really")
    cases = [(tmp_path / "missing.glb", FileNotFoundError, "missing.glb"),
             (empty, ValueError, "empty.obj"),
             (nan, ValueError, "nan.obj"),
             (corrupt_png, ValueError, "pano.png"),
             (tmp_path / "scene.fbx", ValueError, "fbx")]
    for path, error, name in cases:
        with pytest.raises(error, match=name):
            renderer.set_scene(str(path))
    assert renderer.scene.name == "uniform"


def test_oversized_texture_is_refused():
    mesh = MeshData(np.zeros((3, 3), np.float32) + np.eye(3, dtype=np.float32), np.array([[0, 1, 2]]),
                    np.ones((3, 3), np.float32), uv=np.zeros((3, 2), np.float32),
                    texture=np.zeros((9000, 4, 3), np.float32))
    with pytest.raises(ValueError, match="'big'.*larger than 8192"):
        mesh.validate("big")


def test_panorama_keeps_16_bit_and_float_range(tmp_path, dome):
    import cv2

    from antarium.renderers.panorama import Panorama

    ramp = np.linspace(0, 1, 512)
    img16 = np.tile((ramp * 65535).astype(np.uint16)[None, :, None], (256, 1, 3))
    cv2.imwrite(str(tmp_path / "p16.png"), img16)
    p16 = Panorama(str(tmp_path / "p16.png"))
    levels = np.unique(p16.gbua[..., 0])
    assert len(levels) > 400  # 8 bits would give at most 256 levels
    import OpenEXR

    hdr = np.tile(np.linspace(0, 4, 512, dtype=np.float32)[None, :, None], (256, 1, 3))
    path = tmp_path / "hdr.exr"
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, {"RGB": hdr}) as f:
        f.write(str(path))
    p = Panorama(str(path), exposure=0.25)  # linear radiance kept, scaled: 4 -> 1
    assert p.gbua[..., 1].max() == pytest.approx(1.0, abs=1e-3)
    assert p.gbua[..., 1][0, 256] == pytest.approx(0.25 * hdr[0, 256, 0], abs=0.01)
    hdr_tiff = tmp_path / "hdr.tiff"
    cv2.imwrite(str(hdr_tiff), hdr)
    assert Panorama(str(hdr_tiff), exposure=0.5).gbua[..., 1][0, 128] == pytest.approx(0.5 * hdr[0, 128, 0], abs=0.01)
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"v/1\x01 not an exr")
    with pytest.raises(ValueError, match="bad.exr"):
        Panorama(str(bad))


def test_panorama_scene_orientation(renderer, dome, tmp_path):
    import cv2

    img = np.zeros((180, 360, 3), np.uint8)
    img[:, 170:190] = [0, 255, 0]  # a green stripe in the centre column: azimuth 0
    cv2.imwrite(str(tmp_path / "stripe.png"), img[:, :, ::-1])
    renderer.set_scene({"scene": "panorama", "path": str(tmp_path / "stripe.png")})
    assert lit_azimuth_deg(renderer.render(HOME), dome, threshold=0.3) == pytest.approx(0, abs=1.5)


def test_habitat_is_big_enough_and_round_trips_through_glb(renderer, dome, tmp_path):
    from antarium.renderers.habitat import habitat_objects
    from antarium.renderers.meshes import load_mesh_objects, save_glb

    objects = habitat_objects(seed=3)
    n = sum(o.mesh.n_triangles for o in objects.values())
    assert n >= 50_000
    ground = objects["ground"].mesh.vertices
    assert np.ptp(ground[:, 0]) >= 20 and np.ptp(ground[:, 1]) >= 20
    assert ground[:, 2].max() < 0.009  # the default eye (z = 0.01) is about 1 cm above the ground
    assert {"tree_0", "bush_0", "tussocks", "stones"} <= set(objects)
    path = save_glb(objects, tmp_path / "habitat.glb")
    back = load_mesh_objects(path)
    assert set(back) == set(objects)
    assert np.allclose(back["tree_2"].position, objects["tree_2"].position, atol=1e-5)
    a = objects["tree_2"].world_vertices()
    b = back["tree_2"].world_vertices()
    assert np.allclose(a, b, atol=1e-4)
    # same seed, same world
    assert np.array_equal(habitat_objects(seed=3)["stones"].mesh.vertices, objects["stones"].mesh.vertices)


def test_levels_of_detail_stay_within_a_texel(renderer, dome):
    """Full detail and the default levels of detail give nearly the same LED frame."""
    renderer.set_scene("habitat")
    pose = Pose(1.0, -0.5, 0.01, 0.7)
    coarse = renderer.render(pose).astype(np.float64)
    levels = renderer._meshes.levels(np.array([pose.x, pose.y, pose.z]))
    assert levels.max() > 0
    renderer._meshes.lod_angle = 0.0
    full = renderer.render(pose).astype(np.float64)
    renderer._meshes.lod_angle = renderer.lod_angle
    diff = np.abs(coarse - full) / 65535
    assert diff.mean() < 0.003 and np.percentile(diff, 99) < 0.05


def test_meshes_over_the_far_field_table_match_the_background_pass(renderer, dome):
    """Meshes composited per LED over the far-field table == the far field drawn behind them in GL."""
    gl_path = Renderer(dome, face_size=FACE, fast_far_field=False)
    try:
        pose = Pose(0.5, 0.2, 0.01, 1.2)
        renderer.set_scene("habitat")
        gl_path.set_scene("habitat")
        assert renderer._table is not None and gl_path._table is None
        a = renderer.render(pose).astype(np.float64) / 65535
        b = gl_path.render(pose).astype(np.float64) / 65535
        diff = np.abs(a - b)
        # differences only where an LED's footprint straddles a silhouette against a varying far field
        assert diff.mean() < 0.002 and np.percentile(diff, 99) < 0.02
    finally:
        gl_path.release()


def test_a_kilometre_wide_object_keeps_working(renderer, dome):
    """Objects too large for the fine level-of-detail cells keep their full detail instead of failing."""
    v = np.array([[-500, -500, 0], [500, -500, 0], [500, 500, 0], [-500, 500, 0], [0, 0, 300]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]])
    scene = build_scene({"scene": "horizon", "sky": 0.0, "ground": 0.0})
    scene.objects["mountain"] = SceneObject(MeshData(v, f, np.full((5, 3), 0.5, np.float32)),
                                            position=(0.0, 0.0, -1.0))
    scene.__post_init__()
    renderer.set_scene(scene)
    g = green(renderer.render(Pose(0, 0, 0.5, 0.0)), dome)
    assert g.max() > 0.4


def test_each_face_draws_only_the_chunks_it_can_see(renderer):
    """A chunk straight ahead is drawn by the forward face only; one straddling two faces by both."""
    from antarium.renderers.cubemap import FACES

    scene = build_scene({"scene": "horizon"})
    scene.objects["ahead"] = SceneObject(box(0.2), position=(5.0, 0.0, 0.0))
    scene.objects["edge"] = SceneObject(box(0.2), position=(5.0, 5.0, 0.0))  # on the +x/+y face boundary
    scene.__post_init__()
    renderer.set_scene(scene)
    vis = renderer._meshes.visible_chunks(np.eye(3), np.array([0.0, 0.0, 0.1]))
    plus_x, plus_y = 0, 2
    assert np.allclose(FACES[plus_x, 0], [1, 0, 0]) and np.allclose(FACES[plus_y, 0], [0, 1, 0])
    assert vis[0].tolist() == [True, False, False, False, False, False]
    assert vis[1, plus_x] and vis[1, plus_y] and vis[1].sum() == 2


@pytest.mark.parametrize("spec, message", [
    ({"scene": "sky", "rotation_deg": math.nan}, "rotation_deg must be a finite number, got nan"),
    ({"scene": "sky", "rotation_deg": "x"}, "rotation_deg must be a finite number, got 'x'"),
    ({"scene": "uniform", "swap_green_blue": "no"}, "swap_green_blue must be true or false, got 'no'"),
    ({"scene": "uniform", "swap_green_blue": 0.3}, "swap_green_blue must be true or false, got 0.3"),
    ({"scene": "grating", "period_deg": True}, "period_deg must be a finite number, got True"),
    ({"scene": "sky", "lowpass_deg": True}, "lowpass_deg (low-pass cut-off period, degrees) must be a finite "
                                            "number >= 0 and <= 101.9, got True"),
    ({"scene": "sky", "dop_max": True}, "sky dop_max must be a finite number, got True"),
    ({"scene": "w.glb", "path": "x.obj"}, "scene 'w.glb' is a file already; give either it or 'path' ('x.obj')"),
    ({"scene": "p.png", "path": "q.png"}, "scene 'p.png' is a file already; give either it or 'path' ('q.png')"),
    ({"scene": "uniform", "channel_gain": [1e300, 1, 1]},
     "green channel gain must be a finite number >= 0 and <= 1000, got 1e+300"),
    ({"scene": "uniform", "contrast": 1e300}, "contrast (1 = unchanged) must be a finite number >= 0 and <= 1000, "
                                              "got 1e+300"),
    ({"scene": "sky", "sun_radiance": -1}, "sky sun_radiance must be a finite number >= 0 and <= 1000, got -1"),
    ({"scene": "sky", "sun_radiance": math.nan}, "sky sun_radiance must be a finite number >= 0 and <= 1000, "
                                                 "got nan"),
    ({"scene": "bars", "bars": [5]}, "each of bars must be a table of bar parameters, got 5"),
    ({"scene": "mesh", "path": 5}, "path must be a file path (a string), got 5"),
    ({"scene": "habitat", "seed": 1.5}, "seed must be an integer >= 0, got 1.5"),
])
def test_bad_scene_parameters_are_refused_naming_them(spec, message):
    with pytest.raises(ValueError) as err:
        build_scene(spec)
    assert message in str(err.value)


@pytest.mark.parametrize("kwargs, message", [
    ({"uv_ratio": math.nan}, "panorama uv_ratio must be a finite number >= 0, got nan"),
    ({"uv_ratio": -3}, "panorama uv_ratio must be a finite number >= 0, got -3"),
    ({"uv_ratio": "x"}, "panorama uv_ratio must be a finite number >= 0, got 'x'"),
    ({"alpha": 2.0}, "panorama array alpha must be in [0, 1], got values from 2 to 2"),
    ({"alpha": -1.0}, "panorama array alpha must be in [0, 1], got values from -1 to -1"),
])
def test_bad_panorama_values_are_refused(kwargs, message):
    from antarium.renderers.panorama import Panorama

    img = np.full((4, 8, 4), 0.5)
    img[..., 3] = kwargs.pop("alpha", 1.0)
    with pytest.raises(ValueError) as err:
        Panorama(img, **kwargs)
    assert str(err.value) == message


def test_huge_gain_or_contrast_is_refused_and_changes_nothing(renderer):
    renderer.set_scene({"scene": "uniform", "colour": [0.3, 0.3, 0.1]})
    before = renderer.render(HOME).copy()
    with pytest.raises(ValueError, match=r"green channel gain must be a finite number >= 0 and <= 1000, got 1e\+300"):
        renderer.scale_channel("green", 1e300)
    with pytest.raises(ValueError, match=r"contrast \(1 = unchanged\) must be .* <= 1000, got 1e\+300"):
        renderer.set_contrast(1e300)
    assert renderer.scene.channel_gain == (1.0, 1.0, 1.0) and renderer.scene.contrast == 1.0
    assert np.array_equal(renderer.render(HOME), before)


def test_a_mesh_of_zero_area_triangles_is_refused_naming_it():
    flat = MeshData(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], np.float32), np.array([[0, 1, 2]]),
                    np.full((3, 3), 0.5, np.float32))
    with pytest.raises(ValueError) as err:
        flat.validate("line")
    assert str(err.value) == "mesh 'line': all 1 triangle(s) have zero area (points or lines only)"


def test_rotate_scene_without_pivot_keeps_the_previous_pivot(renderer):
    renderer.set_scene("uniform")
    renderer.rotate_scene(0.3, pivot=(1.0, 2.0))
    renderer.rotate_scene(0.5)
    assert renderer.scene.pivot == (1.0, 2.0) and renderer.scene.rotation == 0.5
