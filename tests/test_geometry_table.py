"""Per-LED table export round trip and the layout command."""

import numpy as np
import pytest

from antarium.cli import main
from antarium.geometry import load_dome
from antarium.geometry.table import COLUMNS, export_table, led_table, read_table


@pytest.mark.parametrize("suffix", [".csv", ".json"])
def test_export_round_trip(tmp_path, suffix):
    dome = load_dome()
    path = export_table(dome, tmp_path / f"leds{suffix}")
    back = read_table(path)
    ref = led_table(dome)
    for c in COLUMNS:
        np.testing.assert_array_equal(back[c], ref[c], err_msg=c)
    assert len(back["index"]) == 20350


def test_export_rejects_unknown_format(tmp_path):
    with pytest.raises(ValueError, match=r"\.csv or \.json"):
        export_table(load_dome(), tmp_path / "leds.xlsx")


def test_layout_command_prints_summary_and_writes_pictures(tmp_path, capsys):
    assert main(["layout", "--out", str(tmp_path), "--export", str(tmp_path / "leds.csv")]) == 0
    out = capsys.readouterr().out
    assert "19,855 GB pixels, 495 UV pixels" in out
    assert "GB seam" in out and "layout load time" in out
    for name in ("layout_mollweide.png", "layout_3d.png", "leds.csv"):
        assert (tmp_path / name).stat().st_size > 10_000


def test_layout_command_rejects_options_without_regenerate(capsys):
    assert main(["layout", "--no-pictures", "--margin-mm", "3"]) == 2
    assert "only with --regenerate" in capsys.readouterr().err


@pytest.mark.parametrize("option, value", [("--margin-mm", "-1"), ("--margin-mm", "0"), ("--min-pitch-mm", "150")])
def test_layout_command_reports_a_bad_length_in_mm_as_given(tmp_path, capsys, option, value):
    out = tmp_path / "layout.npz"
    assert main(["layout", "--no-pictures", "--regenerate", "--layout-out", str(out), option, value]) == 2
    err = capsys.readouterr().err
    assert f"{option} must be in (0, 100) mm, got {value} mm" in err
    assert not out.exists()
