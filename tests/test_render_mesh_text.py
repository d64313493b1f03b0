"""OBJ/MTL text in any 8-bit encoding loads; binary garbage named .obj is refused in one clear line."""

import numpy as np
import pytest

from antarium.renderers.library import build_scene
from antarium.renderers.mesh_text import decode_mesh_text, load_text_mesh

TRIANGLE = b"v 0 1 0\nv 1 1 0\nv 0 1 1\nf 1 2 3\n"


def test_an_obj_with_a_latin1_byte_loads(tmp_path):
    path = tmp_path / "latin1.obj"
    path.write_bytes(b"# caf\xe9\n" + TRIANGLE)
    assert build_scene(str(path)).n_triangles == 1


def test_a_latin1_material_file_is_read_too(tmp_path):
    (tmp_path / "red.mtl").write_bytes(b"# rouge fonc\xe9\nnewmtl red\nKd 1.0 0.0 0.0\n")
    path = tmp_path / "red.obj"
    path.write_bytes(b"# caf\xe9\nmtllib red.mtl\n" + TRIANGLE.replace(b"f ", b"usemtl red\nf "))
    assert build_scene(str(path)).n_triangles == 1
    (geom,) = load_text_mesh(path).geometry.values()
    assert np.asarray(geom.visual.material.diffuse)[:3].tolist() == [255, 0, 0]


def test_random_bytes_are_refused_in_one_line(tmp_path):
    path = tmp_path / "noise.obj"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 3000, dtype=np.uint8).tobytes())
    with pytest.raises(ValueError, match=r"noise\.obj is not a text OBJ file") as info:
        build_scene(str(path))
    assert "\n" not in str(info.value) and "charset" not in str(info.value)


def test_utf8_text_is_kept_as_it_is():
    assert decode_mesh_text("# café\n".encode(), "a.obj") == "# café\n"


def test_each_material_gets_its_mtl_colour(tmp_path):
    """Noted since stop 23: every OBJ material drew white, its Kd ignored (trimesh keeps Kd as a diffuse that a material
    without Kd also has, at 0.4). Kd is the material's sRGB colour; one number is a grey; a material without Kd, or
    with a spectral one, is white. trimesh alone drops every material of this file (grey objects)."""
    from antarium.renderers.channels import rgb_to_gbu, srgb_to_linear
    from antarium.renderers.meshes import load_mesh_objects

    (tmp_path / "four.mtl").write_text("newmtl leaf\nKd 0.1 0.7 0.2\nnewmtl bark\nKd 0.4 0.25 0.1\nKs 0.5\n"
                                      "newmtl plain\nNs 10\nKd spectral sky.rfl\nnewmtl grey\nKd 0.3\n")
    (tmp_path / "four.obj").write_text("mtllib four.mtl\nv 0 1 0\nv 1 1 0\nv 0 1 1\nv 1 1 1\nv 2 1 1\n"
                                      "usemtl leaf\nf 1 2 3\nusemtl bark\nf 2 4 3\nusemtl plain\nf 2 5 4\n"
                                      "usemtl grey\nf 1 3 5\n")
    colours = sorted(tuple(o.mesh.colours[0]) for o in load_mesh_objects(tmp_path / "four.obj").values())
    kds = [(0.1, 0.7, 0.2), (0.4, 0.25, 0.1), (1.0, 1.0, 1.0), (0.3, 0.3, 0.3)]  # "plain" states no Kd: white
    expected = sorted(tuple(rgb_to_gbu(srgb_to_linear(np.array(kd)))) for kd in kds)
    assert np.allclose(colours, expected, atol=1e-6)


QUAD = ("mtllib t.mtl\nv 0 1 0\nv 1 1 0\nv 1 1 1\nv 0 1 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
        "usemtl mat\nf 1/1 2/2 3/3\nf 1/1 3/3 4/4\n")


def textured_quad(tmp_path, image, mtl="newmtl mat\nKd 0.8 0.8 0.8\nmap_Kd tex.png\n"):
    """The one object of a 1 m textured OBJ quad whose material is `mtl`, its texture `image` (PIL) or bytes."""
    from antarium.renderers.meshes import load_mesh_objects

    if isinstance(image, bytes):
        (tmp_path / "tex.png").write_bytes(image)
    else:
        image.save(tmp_path / "tex.png")
    (tmp_path / "t.mtl").write_text(mtl)
    (tmp_path / "t.obj").write_text(QUAD)
    (obj,) = load_mesh_objects(tmp_path / "t.obj").values()
    return obj


def test_a_textured_material_takes_its_texture_alone(tmp_path):
    """Kd 0.8 is not applied; the texture (sRGB 200 -> linear 0.578) gives the colour, the vertices are white.
    Before 2026-11-27 vertices and texture both carried UV = 0.25 B: a white texture drew UV 0.0625."""
    from PIL import Image

    obj = textured_quad(tmp_path, Image.fromarray(np.full((4, 4, 3), 200, np.uint8)))
    np.testing.assert_allclose(obj.mesh.colours, 1.0)
    np.testing.assert_allclose(obj.mesh.texture[0, 0], [0.5776, 0.5776, 0.1444], atol=1e-4)


def test_a_16_bit_grey_texture_keeps_its_level(tmp_path):
    """A 16-bit greyscale texture at 32896 (sRGB 0.502) is linear 0.216, as its 8-bit 128; it was clipped white."""
    from PIL import Image

    obj = textured_quad(tmp_path, Image.fromarray(np.full((4, 4), 32896, np.uint16)))
    np.testing.assert_allclose(obj.mesh.texture[0, 0], [0.2159, 0.2159, 0.0540], atol=1e-4)


@pytest.mark.parametrize("data, mtl", [(b"\x89PNG truncated", "newmtl mat\nmap_Kd tex.png\n"),
                                       (b"", "newmtl mat\nmap_Kd -s 1 1 1 nothere.png\n")])
def test_an_unreadable_texture_is_refused_by_name(tmp_path, data, mtl):
    """A missing, truncated or non-image `map_Kd` refuses the mesh; it was dropped (the mesh drawn in Kd)."""
    texture = mtl.split()[-1]
    with pytest.raises(ValueError, match=rf"t\.mtl: material 'mat': cannot read its texture '{texture}'") as info:
        textured_quad(tmp_path, data, mtl)
    assert "\n" not in str(info.value)


def test_obj_objects_load_each_by_its_name(tmp_path):
    """`o tree` and `o rock` are two objects (they were one, `tree`); with several materials in the file each
    material of an object is its own, named object_material."""
    from antarium.renderers.meshes import load_mesh_objects

    (tmp_path / "two.mtl").write_text("newmtl leaf\nKd 0.1 0.7 0.2\nnewmtl bark\nKd 0.4 0.25 0.1\n")
    body = "v 0 0 0\nv 1 0 0\nv 0 0 3\nv 1 0 3\no tree\nf 1 2 3\nf 2 4 3\no rock\nf 1 2 4\n"
    (tmp_path / "plain.obj").write_text(body)
    (tmp_path / "two.obj").write_text("mtllib two.mtl\n" + body.replace("f 2 4", "usemtl bark\nf 2 4")
                                      .replace("o tree\n", "o tree\nusemtl leaf\n"))
    plain = load_mesh_objects(tmp_path / "plain.obj")
    assert {k: o.mesh.n_triangles for k, o in plain.items()} == {"tree": 2, "rock": 1}
    assert sorted(load_mesh_objects(tmp_path / "two.obj")) == ["rock_bark", "tree_bark", "tree_leaf"]


def test_a_kd_that_is_not_three_numbers_is_named(tmp_path):
    (tmp_path / "bad.mtl").write_text("newmtl leaf\nKd green\n")
    (tmp_path / "bad.obj").write_text("mtllib bad.mtl\nusemtl leaf\n" + TRIANGLE.decode())
    with pytest.raises(ValueError,
                       match=r"bad\.mtl: material 'leaf': 'Kd green'; allowed: Kd r g b, or Kd r \(grey\)") as info:
        build_scene(str(tmp_path / "bad.obj"))
    assert "\n" not in str(info.value)
