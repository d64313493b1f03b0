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
