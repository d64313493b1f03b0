"""Synthetic stimuli show what they say on the LEDs: colours a GB pixel can show (green + blue <= 1), bars on black
without a background, no seam at azimuth +-180 deg, a 180 deg grating is a drum, and bad parameters are refused in
one line naming them (issue: scene review 2, items 1, 2, 4, 10 and 12)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.config import ConfigError, resolve
from antarium.core.pose import Pose
from antarium.renderers.library import build_scene
from antarium.renderers.stimuli import Grating
from antarium.server.config_check import check_config

HOME = Pose(0.0, 0.0, 0.01, 0.0)


def led_radiance(renderer, dome, spec) -> tuple[np.ndarray, object]:
    """((20350, 2) float64 LED radiances: G, B on GB pixels; the scene) of `spec` seen from HOME."""
    scene = build_scene(spec)
    renderer.set_scene(scene)
    return renderer.render(HOME, t=0.0).astype(np.float64) / (65535.0 * dome.gain[:, None]), scene


def _direction(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = math.radians(az_deg), math.radians(el_deg)
    return np.array([[math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)]])


@pytest.mark.parametrize("spec", [{"scene": "grating"}, {"scene": "checkerboard"}, {"scene": "bars"}])
def test_default_stimuli_peak_where_a_gb_pixel_shows_them(renderer, dome, spec):
    """Item 1: the defaults' brightest parts reach the green LEDs as the scene says, not flattened by the GB cap."""
    led, scene = led_radiance(renderer, dome, spec)
    gb = np.flatnonzero(~dome.is_uv & (np.abs(dome.elevation) < math.radians(20)))
    level = scene.evaluate_far(dome.directions[gb])
    assert np.all(level[:, 0] + level[:, 1] <= 1.0 + 1e-6)
    # where the scene is at its brightest, LEDs show it up to the blur of their footprint (0.58 when G + B = 2)
    bright = level[:, 0] >= 0.95 * level[:, 0].max()
    assert level[:, 0].max() > 0.4
    assert abs(np.median(led[gb[bright], 0]) - level[bright, 0].max()) < 0.05
    assert np.allclose(np.median(led[gb[bright], 0]), np.median(led[gb[bright], 1]), atol=0.01)


@pytest.mark.parametrize(("spec", "message"), [
    ({"scene": "grating", "colour": 1}, "grating peak, mean 0.5 * (1 + contrast 1) * colour, (green 1, blue 1, uv 1) "
                                        "cannot be shown: a GB pixel draws at most one LED's current, so green + blue "
                                        "must be <= 1 (a grey level <= 0.5), got 2"),
    ({"scene": "grating", "colour": [1, 0.3, 0.6]}, "got 1.3"),
    ({"scene": "checkerboard", "colour_b": 1}, "checkerboard colour_b (green 1, blue 1, uv 1) cannot be shown"),
    ({"scene": "bars", "background": 1}, "bar background (green 1, blue 1, uv 1) cannot be shown"),
    ({"scene": "uniform", "colour": [0.7, 0.4, 0.0]}, "uniform colour (green 0.7, blue 0.4, uv 0) cannot be shown"),
])
def test_colours_a_gb_pixel_cannot_show_are_refused(spec, message):
    with pytest.raises(ValueError) as info:
        build_scene(spec)
    assert message in str(info.value) and "\n" not in str(info.value)


def test_a_grating_is_judged_by_its_peak_not_its_colour():
    """Colour 1 at mean 0.25 and contrast 1 peaks at grey 0.5: shown as asked."""
    scene = build_scene({"scene": "grating", "colour": 1, "mean": 0.25})
    assert scene.evaluate_far(_direction(20 / 4, 0))[0, :3] == pytest.approx([0.5, 0.5, 0.5], abs=1e-6)


def test_bars_without_a_background_lie_on_black(renderer, dome):
    """Item 2: a transparent bars layer alone is composited over black, not filled with the bar colour."""
    led, _ = led_radiance(renderer, dome, {"scene": "bars", "azimuth_deg": 0, "width_deg": 20, "colour": [1, 0, 0],
                                           "background": None})
    gb = ~dome.is_uv & (np.abs(dome.elevation) < math.radians(30))
    az = np.degrees(dome.azimuth)
    assert led[gb & (np.abs(az) < 5), 0].mean() > 0.9
    assert led[gb & (np.abs(az - 90) < 10), 0].max() < 0.01


def _ends(scene, el_deg: float) -> np.ndarray:
    """(2, 4) far field just either side of azimuth +-180 deg at elevation `el_deg`."""
    return np.concatenate([scene.evaluate_far(_direction(az, el_deg)) for az in (179.999, -179.999)])


@pytest.mark.parametrize("orientation_deg", [0, 30, 45, 60, 90, 135, 180])
@pytest.mark.parametrize("period_deg", [7, 20, 50, 360 / 7, 21.213203])
@pytest.mark.parametrize("waveform", ["sine", "square"])
def test_a_grating_is_seamless_at_180_deg_or_refused(orientation_deg, period_deg, waveform):
    """Item 4: every grating accepted meets itself at azimuth +-180 deg; the others are refused in one line naming
    the nearest seamless periods, which are then accepted."""
    spec = {"scene": "grating", "period_deg": period_deg, "orientation_deg": orientation_deg, "waveform": waveform,
            "phase_deg": 10}
    try:
        scene = build_scene(spec)
    except ValueError as exc:
        text = str(exc)
        assert "has a seam at azimuth +-180 deg" in text and "\n" not in text
        nearest = [float(v) for v in text.rsplit("nearest ", 1)[1].removesuffix(" deg").split(" or ")]
        for period in nearest:
            build_scene({**spec, "period_deg": period})
        return
    for el in (0.0, 20.0):
        ends = _ends(scene, el)
        assert np.abs(ends[0] - ends[1]).max() < 0.01, (spec, el, ends)


@pytest.mark.parametrize(("spec", "nearest"), [
    ({"scene": "grating", "period_deg": 50}, "nearest 45 or 51.428571 deg"),
    ({"scene": "grating", "period_deg": 20, "orientation_deg": 45}, "nearest 19.581419 or 21.213203 deg"),
    ({"scene": "checkerboard", "size_deg": 50}, "nearest 45 or 60 deg"),
    ({"scene": "checkerboard", "size_deg": 24}, "nearest 22.5 or 25.714286 deg"),
])
def test_seams_are_refused_naming_the_nearest_seamless_values(spec, nearest):
    with pytest.raises(ValueError, match="has a seam at azimuth") as info:
        build_scene(spec)
    assert str(info.value).endswith(nearest)


@pytest.mark.parametrize("size_deg", [15, 20, 22.5, 90, 180])
def test_an_accepted_checkerboard_alternates_across_180_deg(size_deg):
    """Past azimuth 180 deg the squares go on as two squares back (a square edge may lie at 180 deg itself)."""
    scene = build_scene({"scene": "checkerboard", "size_deg": size_deg, "colour_b": [0.2, 0.3, 0.4]})
    for el in (0.0, 5.0):
        for step in (0.001, size_deg / 2, size_deg * 1.5):
            past = scene.evaluate_far(_direction(180 + step, el))
            assert np.array_equal(past, scene.evaluate_far(_direction(180 + step - 2 * size_deg, el)))


def test_a_grating_at_180_deg_is_a_drum():
    """Item 12: sin(pi) is 1.2e-16, not 0: orientation 180 is a drum turning the other way (free), not re-evaluated
    every frame."""
    grating = Grating(orientation=math.pi, speed=1.0)
    assert grating.yaw_rate == pytest.approx(-1.0) and not grating.time_varying
    scene = build_scene({"scene": "grating", "orientation_deg": 180, "speed_deg_s": 10})
    assert scene.yaw_rate == pytest.approx(-math.radians(10)) and not scene.far_time_varying
    assert build_scene({"scene": "grating", "orientation_deg": 90, "speed_deg_s": 10}).far_time_varying


BAD_PARAMETERS = [
    ({"scene": "grating", "contrast": "0.5"}, "grating contrast must be a finite number >= 0 and <= 1, got '0.5'"),
    ({"scene": "grating", "contrast": True}, "grating contrast must be a finite number >= 0 and <= 1, got True"),
    ({"scene": "grating", "mean": None}, "grating mean must be a finite number >= 0, got None"),
    ({"scene": "grating", "mean": [0.5]}, "grating mean must be a finite number >= 0, got [0.5]"),
    ({"scene": "grating", "colour": "red"}, "grating colour must be a level or (green, blue, uv) linear radiances in "
                                            "[0, 1], got 'red'"),
    ({"scene": "grating", "period_deg": None}, "period_deg must be a finite number, got None"),
    ({"scene": "sky", "zenith": {"a": 1}}, "sky zenith colour must be a level or (green, blue, uv)"),
    ({"scene": "bars", "colour": [0.1, "x", 0.1]}, "bar colour must be a level or (green, blue, uv)"),
    ({"scene": "checkerboard", "colour_a": True}, "checkerboard colour_a must be a level or (green, blue, uv)"),
    ({"scene": "horizon", "sky": [[0.1, 0.1, 0.1]]}, "horizon sky colour must be a level or (green, blue, uv)"),
]


@pytest.mark.parametrize(("spec", "message"), BAD_PARAMETERS)
def test_parameters_that_are_not_numbers_are_refused_naming_them(spec, message):
    """Item 10: one ValueError naming the parameter, never a TypeError traceback, never a bool taken for 1."""
    with pytest.raises(ValueError) as info:
        build_scene(spec)
    assert message in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(("spec", "message"), BAD_PARAMETERS[:4])
def test_check_config_reports_bad_stimulus_parameters_in_one_line(spec, message):
    with pytest.raises(ConfigError) as info:
        check_config(resolve({"bus": {"enabled": False}, "render": {"scene": spec}}))
    assert str(info.value) == f"[render] scene {spec['scene']!r}: {message}"


def test_a_drum_turns_when_the_far_field_has_two_yaw_rates(renderer, dome):
    """A drifting drum over a layer that does not turn: the far field is redrawn every frame (no single yaw rate)
    and the drum must move itself; it stood still (found 2026-11-27). It shows what the drum alone shows."""
    from antarium.renderers.scene import Scene

    drum = build_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": 30, "colour": [0.5, 0.0, 0.0],
                        "mean": 0.5, "contrast": 0.8})
    bar = build_scene({"scene": "bars", "azimuth_deg": 180, "width_deg": 10, "background": None})
    both = Scene(far=[*drum.far, *bar.far], name="drum and a bar")
    assert both.far_time_varying and both.yaw_rate == 0.0
    t = 1.0 / 3.0  # the drum moved 10 deg: half a period
    renderer.set_scene(drum)
    alone = renderer.render(HOME, t=t).astype(np.float64) / (65535.0 * dome.gain[:, None])
    renderer.set_scene(both)
    start = renderer.render(HOME, t=0.0).astype(np.float64) / (65535.0 * dome.gain[:, None])
    later = renderer.render(HOME, t=t).astype(np.float64) / (65535.0 * dome.gain[:, None])
    # where the bar does not cover the drum, away from the zenith (where the two ways of drawing a far field differ
    # by up to 0.18 at t = 0 too: the texture redrawn every frame against the table)
    front = ~dome.is_uv & (np.abs(dome.azimuth) < math.radians(90)) & (np.abs(dome.elevation) < math.radians(60))
    assert np.abs(later - start)[front, 0].max() > 0.3           # it moved (the drum spans 0.05..0.45)
    assert np.abs(later - alone)[front, 0].max() < 0.05          # as the drum alone does
