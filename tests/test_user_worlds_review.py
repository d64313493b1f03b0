"""User worlds as labs bring them: georeferenced scans the rig's eye must reach, 8-bit file names in OBJ/MTL text."""

from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.channels import srgb_to_linear
from antarium.renderers.library import build_scene
from antarium.renderers.meshes import load_mesh_objects
from antarium.renderers.stimuli import Uniform

#: a scan in UTM coordinates (m): easting, northing and the ground's height above the sea
EASTING, NORTHING, GROUND_Z = 512_000.0, 5_800_000.0, 351.0


def utm_scan(tmp_path):
    """A 20 m ground square at GROUND_Z with a 1 m pole 1 m east of the scan's middle, as an OBJ in UTM metres (a
    text file: trimesh writes PLY in float32, whose steps are 0.5 m at 5,800 km)."""
    import trimesh

    e, n, h = EASTING, NORTHING, GROUND_Z
    pole = trimesh.creation.box(extents=(0.04, 0.04, 1.0))
    pole.apply_translation([e + 1.0, n, h + 0.5])
    pole.visual.vertex_colors = np.tile([255, 255, 255, 255], (len(pole.vertices), 1))
    ground = trimesh.Trimesh([[e - 10, n - 10, h], [e + 10, n - 10, h], [e + 10, n + 10, h], [e - 10, n + 10, h]],
                             [[0, 1, 2], [0, 2, 3]], vertex_colors=np.tile([0, 0, 0, 255], (4, 1)), process=False)
    path = tmp_path / "scan.obj"
    trimesh.util.concatenate([pole, ground]).export(path)
    return path


def test_origin_brings_a_georeferenced_scan_to_the_rigs_eye(renderer, dome, tmp_path):
    """The rig's eye lies within 1000 km of (0, 0) (set_pose, [loop] start_x_m/start_y_m) at an eye height above
    z = 0: a scan at northing 5,800 km loaded and rendered, but no pose the rig takes could see it. `origin` moves
    the file's point to (0, 0, 0): from 0.1 m above the ground under (E, N) the pole stands 1 m ahead, its foot at
    atan(-0.1 / 0.98) = -5.8 deg."""
    scene = build_scene({"scene": str(utm_scan(tmp_path)), "origin": [EASTING, NORTHING, GROUND_Z]})
    (obj,) = scene.objects.values()
    w = obj.world_vertices()
    assert w[:, 2].min() == pytest.approx(0.0, abs=1e-6) and w[:, 2].max() == pytest.approx(1.0, abs=1e-6)
    scene.far = [Uniform(0.0)]
    renderer.set_scene(scene)
    frame = renderer.render(Pose(0.0, 0.0, 0.1, 0.0))
    gb = ~dome.is_uv
    lit = frame[gb, 0] / (65535 * dome.gain[gb]) > 0.1
    az, el = np.degrees(dome.azimuth[gb][lit]), np.degrees(dome.elevation[gb][lit])
    assert lit.sum() > 20
    assert np.abs(az).max() < 5.0
    assert el.min() == pytest.approx(math.degrees(math.atan2(-0.1, 0.98)), abs=3.0)


@pytest.mark.parametrize("origin", [[1, 2], [0, 0, float("nan")], "0 0 0", [0, 0, True], [2e7, 0, 0]])
def test_a_bad_origin_is_refused_in_one_line_naming_it(tmp_path, origin):
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match=r"t\.obj: origin must be 3 finite numbers \(m\)") as info:
        build_scene({"scene": str(tmp_path / "t.obj"), "origin": origin})
    assert "\n" not in str(info.value)


def test_an_8_bit_material_and_texture_name_finds_its_file(tmp_path):
    """An OBJ and MTL written in Latin-1 (Windows-1252) name "m\xe9.mtl" and "t\xe9x.png", the files on disk named
    by those same bytes (copied as they were). The text is read as Latin-1, so the names became "mé.mtl" in
    UTF-8, which named no file: the world was refused ("cannot read its material file 'mé.mtl'")."""
    from PIL import Image

    folder = os.fsencode(tmp_path)
    Image.fromarray(np.full((4, 4, 3), [0, 0, 255], np.uint8)).save(os.fsdecode(folder + b"/t\xe9x.png"))
    with open(folder + b"/m\xe9.mtl", "wb") as f:
        f.write(b"newmtl caf\xe9\nmap_Kd t\xe9x.png\n")
    with open(folder + b"/w.obj", "wb") as f:
        f.write(b"mtllib m\xe9.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl caf\xe9\nf 1/1 2/2 3/3\n")
    (obj,) = load_mesh_objects(tmp_path / "w.obj").values()
    assert obj.mesh.texture is not None
    np.testing.assert_allclose(obj.mesh.texture[..., :3].reshape(-1, 3).mean(0), [0.0, 1.0, 0.25], atol=1e-6)


def test_an_object_beyond_the_worlds_reach_is_refused_naming_file_and_object(tmp_path):
    """A triangle 100,000 km out (a file in millimetres read as metres): the error named neither the file nor the
    object ("object position must be 3 finite numbers (m) ... got (np.float64(100050000.0), ...")."""
    path = tmp_path / "far.obj"
    path.write_text("o wall\nv 1e8 0 0\nv 1.001e8 0 0\nv 1e8 1e5 0\nf 1 2 3\n")
    with pytest.raises(ValueError, match=r"far\.obj: object 'wall' lies at \[100050000\.0, 50000\.0, 0\.0\] m; "
                                         r"allowed: within 1e\+07 m .*scale 0\.001.*origin") as info:
        build_scene(str(path))
    assert "\n" not in str(info.value)
    scene = build_scene({"scene": str(path), "scale": 0.001})
    assert scene.objects["wall"].position == pytest.approx((100050.0, 50.0, 0.0))


@pytest.mark.parametrize("suffix", [".png", ".exr"])
def test_a_panorama_with_an_8_bit_file_name_loads(tmp_path, suffix):
    """A panorama named by bytes that are not UTF-8 ("pano\xe9", copied from a Latin-1 system). OpenCV's imread
    of such a name killed the process (segmentation fault); OpenEXR refused it ("pass a filesystem path as str").
    Run in a child process, so that the crash fails the test instead of ending the run."""
    import subprocess
    import sys

    script = f"""
import os, sys
import numpy as np
from antarium.renderers.panorama import Panorama
path = os.fsdecode(os.fsencode({str(tmp_path)!r}) + b"/pano\\xe9{suffix}")
image = np.zeros((8, 16, 3), np.float32)
image[:, 7:9] = 0.5  # a vertical stripe at azimuth 0, linear 0.5 in the EXR, sRGB 0.5 in the PNG
if path.endswith(".exr"):
    import OpenEXR
    OpenEXR.File({{"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}}, {{"RGB": image}}).write(
        {str(tmp_path / "tmp.exr")!r})
    os.rename({str(tmp_path / "tmp.exr")!r}, path)
else:
    import cv2
    with open(path, "wb") as f:
        f.write(cv2.imencode(".png", np.rint(image * 255).astype(np.uint8))[1].tobytes())
print(Panorama(path).gbua[4, 7:9, 1].round(3).tolist())
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-500:]
    level = 0.5 if suffix == ".exr" else srgb_to_linear(128 / 255)  # the stripe's blue, linear
    np.testing.assert_allclose(json.loads(done.stdout.splitlines()[-1]), [level, level], atol=1e-3)


@pytest.mark.parametrize("suffix", [".obj", ".ply", ".stl"])
def test_a_mesh_file_name_that_is_not_utf8_is_refused_in_one_line(tmp_path, suffix):
    """trimesh names an OBJ's, PLY's or STL's objects by the file's name: one named by Latin-1 bytes ("b\xe9.stl")
    raised "'utf-8' codec can't encode character '\\udce9' in position 20" from deep inside trimesh, naming neither
    the file nor what to do."""
    import trimesh

    path = os.fsdecode(os.fsencode(tmp_path) + b"/b\xe9" + suffix.encode())
    trimesh.creation.box().export(path, file_type=suffix.lstrip("."))
    with pytest.raises(ValueError, match=r"mesh file name 'b\\udce9\.(obj|ply|stl)' is not UTF-8 text.*allowed: a "
                                         r"file name in UTF-8 \(rename the file\)"):
        build_scene(path)
