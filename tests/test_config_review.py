"""The rig config against careless input (a folder, a file that is not UTF-8, a key above every section header, a
TOML mistake, port 0 without an emulator: one `ConfigError` line naming it and what is allowed) and
`--print-config` printing a rig file that loads back to the same config."""

import re
import tomllib
import warnings
from pathlib import Path

import pytest
import tomli_w

from antarium.cli import main
from antarium.config import SECTIONS, ConfigDeprecationWarning, ConfigError, load_config, resolve

DOCS = Path(__file__).resolve().parent.parent / "docs"


def test_a_path_that_is_no_readable_file_is_one_config_error(tmp_path):
    """A folder or a path through a file raised a raw IsADirectoryError / NotADirectoryError: a traceback in every
    example script given such a --config (run_script reports ConfigError only)."""
    with pytest.raises(ConfigError, match=rf"^rig config {re.escape(repr(str(tmp_path)))} is a folder; give a "
                                          r"file$"):
        load_config(tmp_path)
    (tmp_path / "rig.toml").write_text("")
    inside = tmp_path / "rig.toml" / "x.toml"
    with pytest.raises(ConfigError, match=rf"^rig config {re.escape(repr(str(inside)))} cannot be read: a part of "
                                          r"the path is a file, not a folder$"):
        load_config(inside)
    with pytest.raises(ConfigError, match=r"^\[locomotion\] trackball file '.*' is a folder; give a file$"):
        resolve({"locomotion": {"source": "usb", "trackball": str(tmp_path)}})


def test_a_file_that_is_not_utf8_text_is_one_config_error(tmp_path):
    """A rig file saved as Latin-1 (or a binary file) raised a raw UnicodeDecodeError naming neither the file nor
    what is allowed."""
    path = tmp_path / "rig.toml"
    path.write_bytes('[rig]\nname = "r\xe9"\n'.encode("latin-1"))
    with pytest.raises(ConfigError, match=r"^rig config '.*rig.toml' is not UTF-8 text \(byte 0xe9 at line 2\); "
                                          r"allowed: a TOML file in UTF-8$"):
        load_config(path)


def test_a_toml_mistake_shows_the_line_it_is_on(tmp_path):
    """tomllib says 'Cannot overwrite a value (at line 3, column 16)'; the line itself names the key."""
    path = tmp_path / "rig.toml"
    path.write_text("[loop]\nrate_hz = 190.0\nrate_hz = 100.0\n")
    with pytest.raises(ConfigError, match=r"^rig config '.*' is not valid TOML: Cannot overwrite a value \(at line "
                                          r"3, column 16\): 'rate_hz = 100.0'$"):
        load_config(path)


@pytest.mark.parametrize("text, message", [
    ("rate_hz = 190.0\n[loop]\n", "rate_hz = 190.0 is above every section header; allowed: under [loop]"),
    ('name = "rig2"\n', "name = 'rig2' is above every section header; allowed: under [rig]"),
    ("stats_every = 5\n", "stats_every = 5 is above every section header; allowed: under [loop]"),
    ("frobnicate = 1\n", "frobnicate = 1 is above every section header; allowed: keys under a [section] header"),
])
def test_a_key_above_every_section_header_is_named_as_such(tmp_path, text, message):
    """`rate_hz = 190.0` before any `[loop]` was reported as 'unknown section [rate_hz]'."""
    path = tmp_path / "rig.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}"):
        load_config(path)


def test_an_unknown_array_of_tables_is_still_an_unknown_section():
    with pytest.raises(ConfigError, match=r"^unknown section \[ant\]; allowed: \[rig\]"):
        resolve({"ant": [{"model": "mb"}]})


@pytest.mark.parametrize("folder", ["", "  "])
def test_an_empty_log_folder_is_refused_naming_the_working_folder_form(folder):
    """`[log] dir = ""` wrote the trials into the server's working folder without a word."""
    message = '[log] dir must name a folder ("." for the server\'s working folder)'
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}"):
        resolve({"log": {"dir": folder}})
    assert resolve({"log": {"dir": "."}}).log.dir == "."


def test_port_0_without_a_spawned_emulator_is_refused_when_the_file_is_loaded(tmp_path, capsys):
    """It passed `load_config`, `serve --print-config` and `antarium check`'s config line; `serve` printed its
    start banner and only then refused it (a rule copied in the server, `antarium check` and the served ant)."""
    message = ("[link] port 0 needs spawn_emulator = true (the emulator's free port); allowed with "
               "spawn_emulator = false: the distributor's UDP port 1..65535 (the board's is in "
               "docs/rig.real.example.toml)")
    with pytest.raises(ConfigError, match=f"^{re.escape(message)}$"):
        resolve({"link": {"spawn_emulator": False}})
    path = tmp_path / "rig.toml"
    path.write_text("[link]\nspawn_emulator = false\n")
    assert main(["serve", "--print-config", "--config", str(path)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err == f"antarium serve: error: {message}\n"
    assert resolve({"link": {"spawn_emulator": False, "port": 19055}}).link.port == 19055
    assert resolve({"link": {"spawn_emulator": False, "interface": "virtual"}}).link.port == 0  # no UDP port used


@pytest.mark.parametrize("text", [
    None,
    (DOCS / "rig.example.toml").read_text(),
    (DOCS / "rig.real.example.toml").read_text(),
    '[render]\nscene = { scene = "grating", period_deg = 20 }\nface_size = 96\n[monitor]\nallow = ["10.0.0.1"]\n'
    '[loop]\nball_radius_m = 0.04\ncpu = 3\nkeep_gpu_busy = false\n[locomotion]\nsource = "replay"\n'
    'path = "walk.csv"\nloop = true\n[link]\ndot_correction = "dc.npy"\n[trackball]\nresolution_cpi = 1200\n',
], ids=["default", "example", "real-example", "renamed-and-tables"])
def test_print_config_prints_a_rig_file_that_loads_back_to_the_same_config(tmp_path, capsys, text):
    path = None
    if text is not None:
        path = tmp_path / "rig.toml"
        path.write_text(text)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the renamed face_size
        config = load_config(path)
    printed = tmp_path / "printed.toml"
    printed.write_text(tomli_w.dumps(config.to_toml_dict()))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # today's names only
        again = load_config(printed)
    assert again == config and again.to_toml_dict() == config.to_toml_dict()
    if path is not None and "replay" not in text:  # the CLI also checks the files a config names exist
        assert main(["serve", "--print-config", "--config", str(path)]) == 0
        assert tomllib.loads(capsys.readouterr().out) == config.to_toml_dict()


def test_the_real_example_sets_only_keys_config_py_has():
    """Every key of docs/rig.real.example.toml exists (with the type the file gives it): the file loads whole."""
    doc = tomllib.loads((DOCS / "rig.real.example.toml").read_text())
    config = load_config(DOCS / "rig.real.example.toml")
    for name, table in doc.items():
        if name in SECTIONS and name != "locomotion":
            assert {k: getattr(config, name).model_dump()[k] for k in table} == table, name


def test_a_renamed_key_is_warned_about_at_its_line_of_the_rig_file(tmp_path):
    """The warning pointed at config.py's own source line (`config.py:306: ... sections = {name: cls.read(...`),
    not at the lab's file."""
    path = tmp_path / "rig.toml"
    path.write_text('[rig]\nname = "r"\n\n[render]\nscene = "horizon"\nface_size = 96\n[loop]\n"eye_height" = 0.02\n')
    with pytest.warns(ConfigDeprecationWarning) as caught:
        config = load_config(path)
    assert config.render.face_size_px == 96 and config.loop.eye_height_m == 0.02
    assert sorted((w.filename, w.lineno, str(w.message)) for w in caught) == [
        (str(path), 6, "[render] face_size is deprecated: call it face_size_px"),
        (str(path), 8, "[loop] eye_height is deprecated: call it eye_height_m")]
