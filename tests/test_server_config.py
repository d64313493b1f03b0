"""The rig config: typed sections with units in their names, checks naming what is allowed, renamed keys still
read with a warning, foreign sections kept for their owners, the documented example."""

import re
import tomllib
import warnings
from pathlib import Path

import pytest

from antarium.config import (
    DEFAULT_WALKER,
    SECTIONS,
    ConfigDeprecationWarning,
    ConfigError,
    LoopSection,
    RigConfig,
    load_config,
    resolve,
)

EXAMPLE = Path(__file__).resolve().parent.parent / "docs" / "rig.example.toml"


def test_the_documented_example_is_the_default():
    example = load_config(EXAMPLE)
    assert example == load_config(None)  # [locomotion] too: it shows the embedded walker whole


def test_the_example_documents_every_key_of_every_section():
    doc = tomllib.loads(EXAMPLE.read_text())
    for name, section in SECTIONS.items():
        if name != "locomotion":
            assert set(doc[name]) == set(section.model_fields), name


def test_sections_are_typed_and_read_as_attributes():
    config = load_config(None)
    assert isinstance(config, RigConfig)
    assert config.loop.rate_hz == 190.0 and config.loop.eye_height_m == 0.01 and config.render.face_size_px == 0
    assert config.to_toml_dict()["loop"]["ball_radius_m"] == 0.05


def test_embedded_default_walks_a_seeded_scripted_walker():
    loco = load_config(None).locomotion
    assert {"source": loco.source, **loco.options} == DEFAULT_WALKER
    bus_only = resolve({"locomotion": {"source": "bus"}}).locomotion
    assert bus_only.source == "bus" and bus_only.options == {}


def test_foreign_sections_are_kept_verbatim_for_their_owners():
    raw = {"trackball": {"cpi": 1200, "sensors": [{"azimuth_deg": 0}]}}
    resolved = resolve(raw)
    assert resolved.section("trackball") == raw["trackball"]
    assert resolved.to_toml_dict()["trackball"] == raw["trackball"]


def test_a_section_no_part_reads_is_refused():
    """[ant] was kept for a part that never read it: its keys were accepted and silently ignored."""
    with pytest.raises(ConfigError, match=r"^unknown section \[ant\]; allowed: "):
        resolve({"ant": {"model": "mb"}})


@pytest.mark.parametrize("raw, message", [
    ({"loop": {"rate": 190}}, "unknown key 'rate' in \\[loop\\]; allowed: "),
    ({"loop": {"rate_hz": "fast"}}, "\\[loop\\] rate_hz must be a finite number"),
    ({"loop": {"rate_hz": 0}}, "\\[loop\\] rate_hz must be in \\[1.0, 2000.0\\], got 0"),
    ({"loop": {"rate_hz": float("nan")}}, "\\[loop\\] rate_hz must be a finite number"),
    ({"loop": {"tether": "loose"}}, "must be one of 'free_yaw', 'fixed'"),
    ({"loop": {"closed_loop": 1}}, "true or false"),
    ({"loop": {"pose_every_frames": 1.5}}, "\\[loop\\] pose_every_frames must be an integer"),
    ({"bus": {"listen": "tcp/127.0.0.1:7447"}}, "list of strings"),
    ({"render": {"scene": {"period_deg": 3}}}, "table with 'scene'"),
    ({"render": {"scene": 5}}, "\\[render\\] scene must be a scene name, a file path or a table"),
    ({"rig": {"name": "a/b"}}, "\\[rig\\] name"),
    ({"loop": 3}, "\\[loop\\] must be a table"),
    ({"rgi": {"name": "x"}}, "unknown section \\[rgi\\]; allowed: \\[rig\\], \\[loop\\]"),
    ({"loop": {"eye_height": 0.02, "eye_height_m": 0.02}}, "both 'eye_height' and 'eye_height_m'"),
])
def test_bad_values_name_the_key_and_what_is_allowed(raw, message):
    with pytest.raises(ConfigError, match=message):
        resolve(raw)


def test_a_rig_name_too_long_for_the_trial_logs_file_names_is_refused_at_load():
    """A 240-byte rig name passed the config and made every trial_start fail with a raw OSError (ENAMETOOLONG)."""
    from antarium.trial_log import RIG_NAME_MAX_BYTES, log_path

    with pytest.raises(ConfigError, match=re.escape(
            "[rig] name must be at most 166 bytes in UTF-8 (it begins the trial logs' file names "
            "<rig>_<yyyymmdd-hhmmss>_<trial>.h5, at most 255 bytes); this one has 167")):
        resolve({"rig": {"name": "r" * (RIG_NAME_MAX_BYTES + 1)}})
    with pytest.raises(ConfigError, match="this one has 168"):  # bytes, not characters
        resolve({"rig": {"name": "é" * 84}})
    name = resolve({"rig": {"name": "r" * RIG_NAME_MAX_BYTES}}).rig.name
    assert len(log_path("/tmp", name, "t" * 200).name.encode()) <= 255 - len("-9999")


@pytest.mark.parametrize("old, new, value", [(old, new, None) for old, new in LoopSection.RENAMED.items()])
def test_old_key_names_are_read_with_a_deprecation_warning(old, new, value):
    value = 3 if new.endswith("_frames") else 0.02
    with pytest.warns(ConfigDeprecationWarning, match=f"\\[loop\\] {old} is deprecated: call it {new}"):
        config = resolve({"loop": {old: value}})
    assert getattr(config.loop, new) == value
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert getattr(resolve({"loop": {new: value}}).loop, new) == value  # today's name: no warning


def test_bad_files_are_reported(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[loop\nrate_hz = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)


def test_the_ball_has_one_radius():
    assert resolve({"trackball": {"ball_radius": 0.04}}).loop.ball_radius_m == 0.04
    assert resolve({"loop": {"ball_radius_m": 0.04}, "trackball": {"ball_radius": 0.04}}).loop.ball_radius_m == 0.04
    with pytest.raises(ConfigError, match=r"\[loop\] ball_radius_m 0.05 m differs from \[trackball\] ball_radius 0.04"):
        resolve({"loop": {"ball_radius_m": 0.05}, "trackball": {"ball_radius": 0.04}})
    with pytest.raises(ConfigError, match=r"\[trackball\] ball_radius must be in"):
        resolve({"trackball": {"ball_radius": 5.0}})


def test_the_driver_gets_the_loop_radius_from_a_trackball_section_without_one(tmp_path):
    from antarium.locomotion import open_source
    from antarium.locomotion.trackball import config as tbconfig

    config = resolve({"loop": {"ball_radius_m": 0.08}, "locomotion": {"source": "usb", "emulate": True},
                      "trackball": {"resolution_cpi": 1200}})
    assert config.section("trackball") == {"resolution_cpi": 1200, "ball_radius": 0.08}
    assert open_source("usb", trackball=config.section("trackball"), emulate=True).config.ball_radius == 0.08
    # `antarium trackball calibrate --config rig.toml` reads [trackball] from the file and writes it back
    path = tmp_path / "rig.toml"
    path.write_text("[loop]\nball_radius_m = 0.08\n[trackball]\nresolution_cpi = 1200\n")
    assert tbconfig.load(path).ball_radius == 0.08
    tbconfig.write_section(path, tbconfig.load(path))
    assert load_config(path).loop.ball_radius_m == 0.08 and tbconfig.load(path).ball_radius == 0.08


def test_the_trackball_file_named_by_locomotion_has_the_loops_radius(tmp_path):
    ball = tmp_path / "ball.toml"
    ball.write_text("[trackball]\nball_radius = 0.1\n")
    usb = {"source": "usb", "trackball": str(ball)}
    assert resolve({"locomotion": usb}).loop.ball_radius_m == 0.1  # the loop takes the hardware's
    assert resolve({"loop": {"ball_radius_m": 0.1}, "locomotion": usb}).loop.ball_radius_m == 0.1
    with pytest.raises(ConfigError, match=rf"^\[loop\] ball_radius_m 0.05 m differs from \[trackball\] ball_radius "
                                          rf"of '{re.escape(str(ball))}' 0.1 m; allowed: one value"):
        resolve({"loop": {"ball_radius_m": 0.05}, "locomotion": usb})
    ball.write_text("[trackball]\nresolution_cpi = 1200\n")  # the driver's default radius
    with pytest.raises(ConfigError, match=r"^\[loop\] ball_radius_m 0.08 m differs from \[trackball\] ball_radius "
                                          r"of '.*ball.toml' \(its default\) 0.05 m"):
        resolve({"loop": {"ball_radius_m": 0.08}, "locomotion": usb})
    with pytest.raises(ConfigError, match=r"^\[locomotion\] trackball file '.*none.toml' not found$"):
        resolve({"locomotion": {"source": "usb", "trackball": str(tmp_path / "none.toml")}})


def test_the_architecture_doc_says_what_happens_to_unknown_sections():
    doc = (EXAMPLE.parent / "architecture.md").read_text()
    assert "kept verbatim" not in doc and "any other section\nis refused, naming the sections allowed" in doc
    with pytest.raises(ConfigError, match=r"^unknown section \[mypart\]; allowed: \[rig\], .*\[trackball\]$"):
        resolve({"mypart": {"k": 1}})
