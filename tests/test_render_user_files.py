"""Mesh files as labs bring them: millimetres and +y up, polygons that are not convex, a missing MTL, big files."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.library import build_scene
from antarium.renderers.mesh_text import triangulate_polygons
from antarium.renderers.meshes import load_mesh_objects
from antarium.renderers.stimuli import Uniform

FACE = 96


def lit_directions_deg(renderer, dome, scene, pose) -> tuple[np.ndarray, np.ndarray]:
    """(azimuth, elevation) in degrees of the GB LEDs whose green radiance exceeds 0.1, the scene on black."""
    scene.far = [Uniform(0.0)]
    renderer.set_scene(scene)
    frame = renderer.render(pose)
    gb = ~dome.is_uv
    lit = frame[gb, 0] / (65535 * dome.gain[gb]) > 0.1
    return np.degrees(dome.azimuth[gb][lit]), np.degrees(dome.elevation[gb][lit])


def test_a_millimetre_y_up_scan_stands_where_it_should(renderer, dome, tmp_path):
    """A photogrammetry-style OBJ in millimetres, +y up: a 40 mm wide, 1 m tall pole whose foot is 1 m ahead. From
    an eye 0.1 m up it spans elevation atan(-0.1 / 0.98) .. atan(0.9 / 0.98) = -5.8 .. 42.6 deg about azimuth 0.
    Read as metres, +z up (no way to say otherwise before), it lay flat, 1 km away, azimuth 1 .. 46 deg."""
    import trimesh

    pole = trimesh.creation.box(extents=(40, 1000, 40))
    pole.apply_translation([1000, 500, 0])
    pole.visual.vertex_colors = np.tile([255, 255, 255, 255], (len(pole.vertices), 1))
    pole.export(tmp_path / "pole.obj")
    scene = build_scene({"scene": str(tmp_path / "pole.obj"), "scale": 0.001, "up": "y"})
    (obj,) = scene.objects.values()
    w = obj.world_vertices()
    assert np.allclose(w.min(axis=0), [0.98, -0.02, 0.0], atol=1e-6)
    assert np.allclose(w.max(axis=0), [1.02, 0.02, 1.0], atol=1e-6)
    az, el = lit_directions_deg(renderer, dome, scene, Pose(0, 0, 0.1, 0.0))
    pitch = 1.5  # the LEDs' spacing (deg): the lit patch is the pole widened by about one footprint
    assert np.abs(az).max() < math.degrees(math.atan2(0.02, 0.98)) + 2 * pitch
    assert el.min() == pytest.approx(math.degrees(math.atan2(-0.1, 0.98)), abs=2 * pitch)
    assert el.max() == pytest.approx(math.degrees(math.atan2(0.9, 0.98)), abs=2 * pitch)


@pytest.mark.parametrize(("spec", "message"), [
    ({"scale": 0}, r"pole\.obj: scale must be a positive number of metres per file unit"),
    ({"scale": "mm"}, r"scale must be a positive number"),
    ({"up": "x"}, r"pole\.obj: up must be the file's up axis, \"z\" or \"y\"; got 'x'"),
    ({"up": ["y"]}, r"pole\.obj: up must be the file's up axis, \"z\" or \"y\"; got \['y'\]"),
])
def test_bad_scale_or_up_is_refused_naming_the_file(tmp_path, spec, message):
    (tmp_path / "pole.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match=message) as info:
        build_scene({"scene": str(tmp_path / "pole.obj"), **spec})
    assert "\n" not in str(info.value)


def test_a_gltf_keeps_its_up_axis_and_scales_its_node_transforms(tmp_path):
    """A GLB's nodes (translation included) scale with the file; GLB/GLTF are +y up by their standard alone."""
    import trimesh

    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    glb = trimesh.Scene()
    glb.add_geometry(tri, node_name="tri", transform=trimesh.transformations.translation_matrix([0, 0, -1000]))
    glb.export(tmp_path / "t.glb")
    (obj,) = load_mesh_objects(tmp_path / "t.glb", scale=0.001).values()
    assert np.allclose(obj.position, [0, 1.0, 0])                 # glTF -z is world +y
    assert np.allclose(obj.world_vertices().max(axis=0), [0.001, 1.0, 0.001])  # glTF +y is world +z
    with pytest.raises(ValueError, match=r"t\.glb: up must be the file's up axis, \"y\" \(GLB/GLTF"):
        load_mesh_objects(tmp_path / "t.glb", up="z")


def test_a_non_convex_polygon_covers_only_itself(renderer, dome, tmp_path):
    """An L-shaped wall, one six-corner face 2 m ahead: trimesh alone cut it into a fan from its first corner,
    which covered the L's notch (its LEDs lit at 0.28 instead of 0)."""
    corners = [(2, 1, 1), (2, 0, 1), (2, 0, 2), (2, -1, 2), (2, -1, 0), (2, 1, 0)]  # (y, z): notch y 0..1, z 1..2
    path = tmp_path / "L.obj"
    path.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in corners) + "f 1 2 3 4 5 6\n")
    (obj,) = load_mesh_objects(path).values()
    v, f = obj.mesh.vertices.astype(np.float64), obj.mesh.faces
    area = 0.5 * np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1).sum()
    assert area == pytest.approx(3.0)                              # the L: 2 x 2 less the 1 x 1 notch
    az, el = lit_directions_deg(renderer, dome, build_scene(str(path)), Pose(0, 0, 1.0, 0.0))
    notch = np.degrees(np.arctan2(0.5, 2.0)), np.degrees(np.arctan2(0.5, math.hypot(2.0, 0.5)))
    wall = -notch[0], notch[1]
    assert not np.any((np.abs(az - notch[0]) < 5) & (np.abs(el - notch[1]) < 5))
    assert np.sum((np.abs(az - wall[0]) < 5) & (np.abs(el - wall[1]) < 5)) > 10


def test_convex_polygons_and_negative_indices_keep_their_fan(tmp_path):
    path = tmp_path / "quad.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n")
    (obj,) = load_mesh_objects(path).values()
    assert obj.mesh.faces.tolist() == [[0, 1, 2], [2, 3, 0]]


def test_a_missing_mtl_is_refused_naming_it(tmp_path):
    """trimesh drew the materials of an OBJ whose MTL file is missing grey and said nothing (a missing texture was
    refused already)."""
    path = tmp_path / "scan.obj"
    path.write_text("mtllib scan.mtl\nusemtl bark\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match=r"scan\.obj: cannot read its material file 'scan\.mtl' "
                                         r"\(FileNotFoundError\); allowed: the MTL file") as info:
        build_scene(str(path))
    assert "\n" not in str(info.value)


def test_a_face_line_comment_is_not_a_corner():
    """A trailing comment on a face line is not read as corners (it made the polygon check fail on int('#'))."""
    text = "v 0 0 0\nv 2 0 0\nv 2 1 0\nv 1 1 0\nv 1 2 0\nv 0 2 0\nf 1 2 3 4 5 6 # an L\nf 1 2 3 # t\n"
    out = triangulate_polygons(text)
    faces = [line.split("#")[0].split()[1:] for line in out.splitlines() if line.startswith("f ")]
    assert len(faces) == 5 and all(len(face) == 3 for face in faces)  # the L's 4 triangles, then the triangle
    assert out.endswith("# an L\nf 1 2 3 # t\n")


def test_a_draco_compressed_gltf_is_refused_naming_the_extension(tmp_path):
    """trimesh loads a Draco-compressed mesh (Sketchfab's and many photogrammetry exports) as zeros without
    DracoPy: the file was refused as "all 2 triangle(s) have zero area", which points nowhere near the cause."""
    import json

    import trimesh

    tri = trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]], process=False)
    files = trimesh.Scene(tri).export(file_type="gltf")
    doc = json.loads(files["model.gltf"])
    doc["extensionsUsed"] = doc["extensionsRequired"] = ["KHR_draco_mesh_compression"]
    for accessor in doc["accessors"]:  # the data would be in the extension's buffer view
        accessor.pop("bufferView", None)
    doc["meshes"][0]["primitives"][0]["extensions"] = {
        "KHR_draco_mesh_compression": {"bufferView": 0, "attributes": {"POSITION": 0}}}
    files["model.gltf"] = json.dumps(doc).encode()
    for name, data in files.items():
        (tmp_path / name).write_bytes(data)
    with pytest.raises(ValueError, match=r"model\.gltf requires the glTF extension KHR_draco_mesh_compression "
                                         r"\(Draco mesh compression\), which cannot be decoded here; allowed") as info:
        build_scene(str(tmp_path / "model.gltf"))
    assert "\n" not in str(info.value)
