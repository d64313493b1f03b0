"""Meshes drawn as their files and numbers say: far from the origin, at every level of detail, with their
textures' depth and alpha; panoramas' grey and UV layers (the real EGL renderer, small faces)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.library import build_scene
from antarium.renderers.meshes import load_mesh_objects
from antarium.renderers.scene import MeshData, SceneObject


def radiance(frame, dome) -> np.ndarray:
    """(N, 2) float64 LED radiances of a frame (GB LEDs: green, blue)."""
    return frame.astype(np.float64) / (65535 * dome.gain[:, None])


def dark_world(objects: dict):
    scene = build_scene({"scene": "horizon", "sky": 0.0, "ground": 0.0})
    scene.objects.update(objects)
    scene.__post_init__()
    return scene


def box_vertices() -> tuple[np.ndarray, np.ndarray]:
    """(8, 3) float64 vertices and (12, 3) faces of a 2 x 2 x 4 cm box 0.2 m along +x from (0, 0, 0), on z = 0."""
    import trimesh

    b = trimesh.creation.box(extents=(0.02, 0.02, 0.04))
    return np.asarray(b.vertices) + [0.2, 0.0, 0.02], np.asarray(b.faces)


def lit_leds(renderer, dome, scene, eye) -> np.ndarray:
    renderer.set_scene(scene)
    g = radiance(renderer.render(Pose(eye[0], eye[1], 0.01, 0.0)), dome)[~dome.is_uv, 0]
    return np.flatnonzero(g > 0.3)


@pytest.mark.parametrize("offset", [(5e4, 0.0, 0.0), (5e5, 4e6, 0.0)])
def test_a_box_far_from_the_origin_lights_the_leds_it_lights_at_the_origin(renderer, dome, tmp_path, offset):
    """Georeferenced worlds: the same box before the same eye, shifted by kilometres, as an object's position and
    as the coordinates of an OBJ file's vertices (loaded in float64), lights the same LEDs."""
    v, f = box_vertices()
    green = np.tile([0.85, 0.0, 0.0], (len(v), 1))  # the OBJ file's sRGB (0, 1, 0)
    home = lit_leds(renderer, dome, dark_world({"box": SceneObject(MeshData(v.astype(np.float32), f, green))}), (0, 0))
    assert len(home) > 20
    off = np.array(offset)
    placed = SceneObject(MeshData(v.astype(np.float32), f, green), position=tuple(off))
    np.testing.assert_array_equal(lit_leds(renderer, dome, dark_world({"box": placed}), off), home)
    obj = tmp_path / "box.obj"
    obj.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f} 0 1 0\n" for x, y, z in v + off)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f))
    loaded = load_mesh_objects(obj)
    np.testing.assert_array_equal(lit_leds(renderer, dome, dark_world(loaded), off), home)


@pytest.mark.parametrize("pose", [Pose(-3.0, 0.5, 0.01, 0.0), Pose(1.0, -0.5, 0.01, 0.7)])
def test_levels_of_detail_change_no_led_by_more_than_a_few_percent(renderer, dome, pose):
    """The habitat's levels of detail against full detail, LED by LED (the worst, not the mean): merged vertices
    that moved up to 1.7 texels folded triangles of closed objects over, and culling their back faces showed the
    sky through stones and tussocks (67-113 LEDs off by more than 0.05, up to 0.38, at face 96)."""
    renderer.set_scene("habitat")
    eye = np.array([pose.x, pose.y, pose.z])
    assert renderer._meshes.levels(eye).max() > 0
    coarse = radiance(renderer.render(pose), dome)
    renderer._meshes.lod_angle = 0.0
    try:
        full = radiance(renderer.render(pose), dome)
    finally:
        renderer._meshes.lod_angle = renderer.lod_angle
    worst = np.abs(coarse - full)[~dome.is_uv].max()
    assert worst < 0.15  # 0.11 here (face 64), 0.06 at face 96; 0.44 and 0.52 before


def test_a_panoramas_uv_layer_follows_the_images_rule(tmp_path):
    """Float UV layers are linear and scaled by `exposure` as the float image is; 8-bit ones sRGB-decoded as
    8-bit images are (the UV layer was taken as it came: exposure ignored, 8-bit values not decoded)."""
    import cv2

    from antarium.renderers.channels import srgb_to_linear
    from antarium.renderers.panorama import Panorama

    cv2.imwrite(str(tmp_path / "grey.tiff"), np.full((16, 32, 3), 0.8, np.float32))
    cv2.imwrite(str(tmp_path / "uv.tiff"), np.full((16, 32), 0.8, np.float32))
    p = Panorama(str(tmp_path / "grey.tiff"), uv=str(tmp_path / "uv.tiff"), exposure=0.5)
    np.testing.assert_allclose(p.gbua[..., 1:3], 0.4, atol=1e-6)  # blue and UV alike
    cv2.imwrite(str(tmp_path / "grey.png"), np.full((16, 32, 3), 128, np.uint8))
    cv2.imwrite(str(tmp_path / "uv.png"), np.full((16, 32), 128, np.uint8))
    p = Panorama(str(tmp_path / "grey.png"), uv=str(tmp_path / "uv.png"))
    np.testing.assert_allclose(p.gbua[..., 1:3], srgb_to_linear(128 / 255), atol=1e-6)


def test_grey_panoramas_load_as_their_rgb_twins(tmp_path):
    """1-channel 8-bit and EXR luminance (Y) panoramas, and grey + alpha arrays, are grey RGB(A) panoramas (they
    were refused: "must be RGB or RGBA, got 1 channel(s)")."""
    import cv2
    import OpenEXR

    from antarium.renderers.panorama import Panorama

    grey = np.tile(np.arange(32, dtype=np.uint8)[None, :] * 8, (16, 1))
    cv2.imwrite(str(tmp_path / "grey.png"), grey)
    cv2.imwrite(str(tmp_path / "rgb.png"), np.repeat(grey[..., None], 3, axis=2))
    np.testing.assert_array_equal(Panorama(str(tmp_path / "grey.png")).gbua, Panorama(str(tmp_path / "rgb.png")).gbua)
    y = np.tile(np.linspace(0, 1, 32, dtype=np.float32)[None, :], (16, 1))
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}, {"Y": y}) as f:
        f.write(str(tmp_path / "y.exr"))
    np.testing.assert_allclose(Panorama(str(tmp_path / "y.exr")).gbua[..., 1], y, atol=1e-6)
    la = np.stack([grey / 255.0, np.full(grey.shape, 0.25)], axis=2)
    p = Panorama(la)
    np.testing.assert_array_equal(p.gbua, Panorama(np.concatenate([np.repeat(la[..., :1], 3, 2), la[..., 1:]], 2)).gbua)
    assert p.gbua[..., 3].max() == 0.25


def textured_quad(tmp_path, image) -> dict:
    """The objects of an OBJ quad whose MTL's map_Kd is `image` (a PIL image, saved as TIFF)."""
    image.save(tmp_path / "tex.tiff")
    (tmp_path / "q.mtl").write_text("newmtl m\nKd 1 1 1\nmap_Kd tex.tiff\n")
    (tmp_path / "q.obj").write_text("mtllib q.mtl\no quad\nv 1 0.5 0\nv 1 -0.5 0\nv 1 -0.5 1\nv 1 0.5 1\n"
                                    "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl m\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")
    return load_mesh_objects(tmp_path / "q.obj")


def test_float_and_32_bit_textures_keep_their_values(tmp_path):
    """A float (F) TIFF texture is linear radiance (it came out black); a 32-bit integer (I) one is scaled by its
    own depth (it was divided by 65535 and came out up to 32768); float values outside [0, 1] are refused."""
    from PIL import Image

    from antarium.renderers.channels import srgb_to_linear

    flat = textured_quad(tmp_path, Image.fromarray(np.full((8, 8), 0.5, np.float32)))["quad"].mesh.texture
    np.testing.assert_allclose(flat[..., :2], 0.5, atol=1e-6)  # G = 0.15 R + 0.85 G, B = B of grey 0.5
    full = textured_quad(tmp_path, Image.fromarray(np.full((8, 8), 2**31 - 1, np.int32)))["quad"].mesh.texture
    np.testing.assert_allclose(full[..., 1], srgb_to_linear((2**31 - 1) / (2**32 - 1)), atol=1e-6)
    with pytest.raises(ValueError, match=r"q\.obj: texture of object 'quad': float texture values must be linear "
                                         r"radiances in \[0, 1\], got 2 to 2"):
        textured_quad(tmp_path, Image.fromarray(np.full((8, 8), 2.0, np.float32)))


def leaf_glb(path, mode: str, uri: str | None = None) -> None:
    """A GLB quad 1 m ahead (x = 1, |y| <= 0.5, 0 <= z <= 1) textured green and opaque in its lower half,
    transparent above, with alphaMode `mode`; uri: its image as that external file instead of inside the GLB."""
    import trimesh
    from PIL import Image

    gltf_from_world = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    corners = np.array([[1, 0.5, 0], [1, -0.5, 0], [1, -0.5, 1], [1, 0.5, 1]], float)
    img = np.zeros((64, 64, 4), np.uint8)
    img[32:, :, 1] = img[32:, :, 3] = 255  # image rows run top down: the lower half green and opaque
    material = trimesh.visual.material.PBRMaterial(baseColorTexture=Image.fromarray(img, "RGBA"), alphaMode=mode,
                                                   alphaCutoff=0.5)
    quad = trimesh.Trimesh(corners @ gltf_from_world.T, [[0, 1, 2], [0, 2, 3]], process=False,
                           visual=trimesh.visual.TextureVisuals(uv=[[0, 0], [1, 0], [1, 1], [0, 1]], material=material))
    scene = trimesh.Scene()
    scene.add_geometry(quad, node_name="leaf")
    path.write_bytes(scene.export(file_type="glb"))


def edit_glb_json(path, edit) -> None:
    """Rewrite a GLB file's JSON chunk through `edit` (dict -> None), its binary chunk kept."""
    import json
    import struct

    raw = path.read_bytes()
    n = struct.unpack_from("<I", raw, 12)[0]
    doc = json.loads(raw[20:20 + n])
    edit(doc)
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    body = struct.pack("<I4s", len(text), b"JSON") + text + raw[20 + n:]
    path.write_bytes(raw[:8] + struct.pack("<I", 12 + len(body)) + body)


@pytest.mark.parametrize(("edit", "what"), [
    (lambda d: d["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"].update(index=7),
     "texture 7 leads to no image"),
    (lambda d: d["textures"][0].update(source=3), "texture 0 leads to no image"),
    (lambda d: d["images"].__setitem__(0, {"uri": "gone%20away.png"}), "image 'gone away.png' not found"),
], ids=["texture index", "image index", "missing image file"])
def test_a_gltf_base_colour_texture_that_leads_nowhere_is_refused(tmp_path, edit, what):
    """A material's base colour texture with a bad index or a missing image file is refused naming the
    material (trimesh drew it untextured, silently)."""
    leaf_glb(tmp_path / "leaf.glb", "OPAQUE")
    edit_glb_json(tmp_path / "leaf.glb", edit)
    with pytest.raises(ValueError, match=re.escape(f"leaf.glb: material '#0': its base colour texture cannot be "
                                                   f"read ({what})")):
        load_mesh_objects(tmp_path / "leaf.glb")


@pytest.mark.parametrize("mode", ["MASK", "BLEND"])
def test_a_gltf_cut_out_shows_the_sky_where_its_texture_is_transparent(renderer, dome, tmp_path, mode):
    """A glTF quad 1 m ahead whose texture is green and opaque in its lower half, transparent above (alphaMode
    MASK, or BLEND drawn as MASK at 0.5): the sky shows through the upper half (it was drawn black)."""
    leaf_glb(tmp_path / "leaf.glb", mode)
    renderer.set_scene({"scene": str(tmp_path / "leaf.glb"), "sun_radiance": 0, "zenith": [0.0, 0.4, 0.1],
                        "ground": [0, 0, 0]})
    r = radiance(renderer.render(Pose(0.0, 0.0, 0.5, 0.0)), dome)
    az, el = np.degrees(dome.azimuth), np.degrees(dome.elevation)
    ahead = ~dome.is_uv & (np.abs(az) < 10)
    upper, lower = ahead & (el > 10) & (el < 20), ahead & (el < -10) & (el > -20)
    assert r[upper, 1].min() > 0.05 and r[upper, 0].max() < 0.01  # the blue sky, no green leaf
    assert r[lower, 0].min() > 0.5  # the opaque half: green


def test_vertices_beyond_the_coordinate_bound_are_refused_in_one_line(tmp_path):
    """A vertex at 1e30 m is refused when the mesh is checked (it printed numpy RuntimeWarnings and drew
    nothing); so is a texture value outside [0, 1]."""
    import warnings

    from antarium.renderers.scene import MAX_COORDINATE_M

    (tmp_path / "far.obj").write_text("v 2 0 0\nv 2 1 0\nv 2 0 1\nv 1e30 1e30 0\nv 1e30 1e30 1\nv 1e30 -1e30 0\n"
                                      "f 1 2 3\nf 4 5 6\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        message = (f"far.obj: mesh 'far.obj': vertex coordinates reach 1e+30 m; allowed: within "
                   f"{MAX_COORDINATE_M:g} m of the object's origin")
        with pytest.raises(ValueError, match=re.escape(message)):
            load_mesh_objects(tmp_path / "far.obj")
    square = MeshData(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32), np.array([[0, 1, 2]]),
                      np.ones((3, 3), np.float32), uv=np.zeros((3, 2), np.float32),
                      texture=np.full((2, 2, 3), 2.0, np.float32))
    with pytest.raises(ValueError, match=r"mesh 'sq': texture values must be in \[0, 1\], got 2 to 2"):
        square.validate("sq")
