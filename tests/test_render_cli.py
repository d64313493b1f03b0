"""`antarium render` and `antarium scene` from the command line (real renderer, small faces)."""

from __future__ import annotations

import numpy as np
import pytest

from antarium.cli import main


def test_render_writes_an_equal_area_map_and_the_cube_map(tmp_path, capsys):
    import cv2

    out, cube = tmp_path / "view.png", tmp_path / "cube.png"
    rc = main(["render", "grating", "--set", "period_deg=30", "--set", "colour=[1, 0, 0]", "--pos", "0", "0", "0.01",
               "--heading", "45", "--out", str(out), "--cube", str(cube), "--face-size", "64", "--width", "400"])
    assert rc == 0
    img = cv2.imread(str(out))  # BGR
    h, w = img.shape[:2]
    assert w == 400  # --width
    centre = img[int(0.18 * h):int(0.32 * h), int(0.3 * w):int(0.7 * w)]  # the map above the front (ticks under)
    # green LEDs lit, no blue in a green grating (the grey grid lines and UV pixels' rings aside)
    assert centre[..., 1].max() > 150 and np.median(centre[..., 0]) < 30
    assert cv2.imread(str(cube)).shape == (6 * 64, 64, 3)
    assert "LED map written" in capsys.readouterr().out


@pytest.mark.parametrize("args, message", [
    (["render", "nonsense"], "unknown scene 'nonsense'"),
    (["render", "grating", "--set", "period_deg=-3"], "(scene 'grating' with --set period_deg=-3)"),  # names --set
    (["render", "uniform", "--heading", "nan"], "heading"),
    (["render", "{not json"], "JSON"),
    (["render", "uniform", "--face-size", "8"], "face_size"),
    (["render", "sky", "--time", "nan"], "--time must be a finite number of seconds, got nan"),
    (["render", "sky", "--set", 'lowpass_deg="10"'], "lowpass_deg (low-pass cut-off period, degrees) must be a "
                                                     "finite number >= 0 and <= 101.9, got '10'"),
    (["render", "bars", "--set", "bars=[5]"], "each of bars must be a table of bar parameters, got 5"),
    (["render", '{"scene": "mesh", "path": 5}'], "path must be a file path (a string), got 5"),
])
def test_render_bad_input_is_a_clear_error(tmp_path, capsys, args, message):
    assert main(["render", "--out", str(tmp_path / "x.png"), "--face-size", "64", *args[1:]]) == 2
    assert message in capsys.readouterr().err


def test_scene_writes_the_habitat_glb_that_loads_back(tmp_path, capsys):
    from antarium.renderers.library import build_scene

    path = tmp_path / "habitat.glb"
    assert main(["scene", "habitat", "--out", str(path)]) == 0
    pano = tmp_path / "habitat_panorama.png"
    assert path.stat().st_size > 500_000 and pano.exists()
    scene = build_scene({"scene": str(path), "panorama": str(pano)})
    assert scene.n_triangles >= 50_000 and "tree_0" in scene.objects
    assert np.ptp(scene.objects["ground"].world_vertices()[:, 0]) >= 20
