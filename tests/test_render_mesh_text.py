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
