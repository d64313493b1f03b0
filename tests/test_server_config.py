"""The rig config: defaults, checks naming what is allowed, unknown sections kept verbatim, the example."""

from pathlib import Path

import pytest

from antarium.config import DEFAULT_WALKER, ConfigError, load_config, resolve

EXAMPLE = Path(__file__).resolve().parent.parent / "docs" / "rig.example.toml"


def test_the_documented_example_is_the_default():
    example = load_config(EXAMPLE)
    default = load_config(None)
    default["locomotion"] = {"source": "scripted"}  # the example names the source without the walker's options
    assert example == default


def test_embedded_default_walks_a_seeded_scripted_walker():
    assert load_config(None)["locomotion"] == DEFAULT_WALKER
    assert resolve({"locomotion": {"source": "bus"}})["locomotion"] == {"source": "bus"}


def test_unknown_sections_are_kept_verbatim_for_their_owners():
    raw = {"trackball": {"cpi": 1200, "sensors": [{"azimuth_deg": 0}]}, "ant": {"model": "mb"}}
    resolved = resolve(raw)
    assert resolved["trackball"] == raw["trackball"] and resolved["ant"] == {"model": "mb"}


@pytest.mark.parametrize("raw, message", [
    ({"loop": {"rate": 190}}, "unknown key 'rate' in \\[loop\\]; allowed: "),
    ({"loop": {"rate_hz": "fast"}}, "\\[loop\\] rate_hz must be a finite number"),
    ({"loop": {"rate_hz": 0}}, "\\[loop\\] rate_hz must be in"),
    ({"loop": {"tether": "loose"}}, "must be one of 'free_yaw', 'fixed'"),
    ({"loop": {"closed_loop": 1}}, "true or false"),
    ({"bus": {"listen": "tcp/127.0.0.1:7447"}}, "list of strings"),
    ({"render": {"scene": {"period_deg": 3}}}, "table with 'scene'"),
    ({"rig": {"name": "a/b"}}, "\\[rig\\] name"),
    ({"loop": 3}, "\\[loop\\] must be a table"),
])
def test_bad_values_name_the_key_and_what_is_allowed(raw, message):
    with pytest.raises(ConfigError, match=message):
        resolve(raw)


def test_bad_files_are_reported(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "none.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[loop\nrate_hz = 1")
    with pytest.raises(ConfigError, match="not valid TOML"):
        load_config(bad)


def test_the_ball_has_one_radius():
    assert resolve({"trackball": {"ball_radius": 0.04}})["loop"]["ball_radius"] == 0.04
    assert resolve({"loop": {"ball_radius": 0.04}, "trackball": {"ball_radius": 0.04}})["loop"]["ball_radius"] == 0.04
    with pytest.raises(ConfigError, match=r"\[loop\] ball_radius 0.05 m differs from \[trackball\] ball_radius 0.04"):
        resolve({"loop": {"ball_radius": 0.05}, "trackball": {"ball_radius": 0.04}})
    with pytest.raises(ConfigError, match=r"\[trackball\] ball_radius must be in"):
        resolve({"trackball": {"ball_radius": 5.0}})
