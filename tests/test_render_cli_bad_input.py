"""`antarium render` refuses nonsense in one line, before rendering or writing anything."""

from __future__ import annotations

import pytest

from antarium.cli import main


@pytest.mark.parametrize("option, name", [("--out", "x"), ("--cube", "cube"), ("--out", "view.jpgg")])
def test_an_image_name_without_png_is_refused_before_anything_is_written(tmp_path, capsys, option, name):
    args = {"--out": str(tmp_path / "view.png"), "--cube": str(tmp_path / "cube.png")}
    args[option] = str(tmp_path / name)
    assert main(["render", "uniform", "--face-size", "64", *(a for kv in args.items() for a in kv)]) == 2
    err = capsys.readouterr().err
    assert f"{option} " in err and ".png" in err and "cv2" not in err and len(err.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []   # not the LED map either when only the cube name is wrong


def test_a_panorama_that_is_not_two_to_one_is_refused(tmp_path, capsys):
    import cv2
    import numpy as np

    path = tmp_path / "p517.png"
    cv2.imwrite(str(path), np.full((333, 517, 3), 128, np.uint8))
    assert main(["render", str(path), "--out", str(tmp_path / "v.png"), "--face-size", "64"]) == 2
    err = capsys.readouterr().err
    assert "517x333" in err and "twice its height" in err
    assert not (tmp_path / "v.png").exists()


def test_a_panorama_a_pixel_off_two_to_one_is_accepted():
    import numpy as np

    from antarium.renderers.panorama import Panorama

    Panorama(np.full((100, 201, 3), 0.5))


def test_an_eye_below_the_ground_is_refused(tmp_path, capsys):
    assert main(["render", "habitat", "--pos", "0", "0", "-5", "--out", str(tmp_path / "v.png")]) == 2
    assert "--pos Z" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args, message", [(["--seconds", "-1"], "--seconds"), (["--seconds", "nan"], "--seconds"),
                                           (["--frames", "0"], "--frames"), (["--work-ms", "-2"], "--work-ms")])
def test_bench_refuses_negative_durations(capsys, args, message):
    assert main(["bench", "loop", *args]) == 2
    assert message in capsys.readouterr().err
