"""Review findings on the geometry and `antarium layout`: a driver position that is not an integer, output names
that are empty or start with `~`, an LED table that is cut short."""

import numpy as np
import pytest

from antarium.cli import main
from antarium.geometry import addressing as a
from antarium.geometry import load_dome
from antarium.geometry.table import export_table, read_table


@pytest.mark.parametrize("chip", [1.5, True, np.array([1.0, 2.0])])
def test_driver_to_led_refuses_a_chip_that_is_not_an_integer(chip):
    # before: chip 1.5 on chain 0 gave (local 12.0, led 0.0), a wrong LED and no error
    with pytest.raises(ValueError, match="chip_in_chain must be an integer"):
        a.driver_to_led(0, chip, 0)


@pytest.mark.parametrize(
    "chain, chip, channel, message",
    [
        (3, 11, 0, "chip_in_chain out of range: chain 3 has chips 0..10, got 11"),
        (np.array([0, 3]), np.array([1, 11]), np.array([0, 0]), "chain 3 has chips 0..10, got 11"),
        (3, 10, 4, "not connected: chain 3, chip 10, channel 4 (LED index 740; allowed up to 739)"),
    ],
)
def test_driver_to_led_names_the_first_bad_position_in_plain_numbers(chain, chip, channel, message):
    # before: "... for chain array([0, 3]): allowed 0..[11 10]" and "LED index np.int64(740) >= 740"
    with pytest.raises(ValueError) as err:
        a.driver_to_led(chain, chip, channel)
    assert message in str(err.value)
    assert "array(" not in str(err.value) and "np." not in str(err.value)


def _error_line(capsys) -> str:
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and out == "", (out, err)
    return lines[0]


@pytest.mark.parametrize("option, what", [("--export", "file"), ("--out", "folder")])
def test_an_empty_output_name_is_refused_and_nothing_is_written(tmp_path, monkeypatch, capsys, option, what):
    # before: an empty --export or --out was taken as "not given" and the pictures went to the current folder
    monkeypatch.chdir(tmp_path)
    assert main(["layout", option, ""]) == 2
    assert f"{option} needs a {what} name, got ''" in _error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_export_to_a_home_folder_writes_where_it_was_checked(tmp_path, monkeypatch, capsys):
    # before: `--export=~/leds.csv` passed the check (~ expanded) but the writer used '~' literally and failed after
    # the work with an error naming no option
    home, work = tmp_path / "home", tmp_path / "work"
    home.mkdir()
    work.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(work)
    assert main(["layout", "--export=~/leds.csv"]) == 0
    assert f"per-LED table: {home / 'leds.csv'}" in capsys.readouterr().out
    assert read_table(home / "leds.csv")["index"].size == 20350
    assert list(work.iterdir()) == []


@pytest.mark.parametrize("cut", ["empty", "header only", "short row"])
def test_a_cut_csv_table_is_refused_in_one_clear_error(tmp_path, cut):
    # before: IndexError (empty file) or "zip() argument 2 is shorter than argument 1" (a row cut short)
    path = export_table(load_dome(), tmp_path / "leds.csv")
    lines = path.read_text().splitlines(keepends=True)
    path.write_text({"empty": "", "header only": lines[0], "short row": "".join(lines[:-1]) + "20349,54,10\n"}[cut])
    with pytest.raises(ValueError, match=r"leds\.csv.*(no rows|row 20351 has 3 fields; allowed 21)"):
        read_table(path)


def test_a_json_table_without_a_column_names_it(tmp_path):
    # before: KeyError 'gain'
    import json

    path = export_table(load_dome(), tmp_path / "leds.json")
    doc = json.loads(path.read_text())
    del doc["data"]["gain"]
    path.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=r"leds\.json.*lacks the columns \['gain'\]"):
        read_table(path)


def test_load_dome_reads_a_rewritten_layout_file_again(tmp_path):
    # before: load_dome cached per path, so a layout regenerated to the same file in one process (a notebook, two
    # `antarium layout --regenerate` calls in one session) still gave the first file's LEDs
    import os
    from dataclasses import replace

    from antarium.geometry import load_layout
    from antarium.geometry.layout import save_layout

    path = tmp_path / "layout.npz"
    shipped = load_layout()
    save_layout(shipped, path)
    first = load_dome(path).positions.copy()
    shrunk = replace(shipped, gb=shipped.gb * 0.5, uv=shipped.uv * 0.5)
    save_layout(shrunk, path)
    stat = path.stat()
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))  # written a second later
    again = load_dome(path)
    np.testing.assert_array_equal(again.layout.gb, shrunk.gb)
    assert not np.array_equal(again.positions, first)
    assert load_dome(path) is again  # an unchanged file stays cached


def test_the_layout_search_finds_a_board_with_a_wide_margin():
    """At a 20 mm margin lattices of exactly 361 GB pixels exist (pitch 9.9-10.3 mm); the search window the shipped
    layout was found in shrank too fast there and the search said none existed."""
    from scipy.spatial.distance import cdist, pdist

    from antarium.geometry.layout import LayoutParams, generate_layout

    params = LayoutParams(margin=0.020)
    layout = generate_layout(params)
    assert layout.gb.shape == (361, 2) and layout.uv.shape == (9, 2)
    assert pdist(layout.gb).min() >= params.gb_min_pitch and pdist(layout.uv).min() >= params.uv_min_pitch
    assert cdist(layout.uv, layout.gb).min() >= params.uv_clearance
