"""Stimulus parameters as a neuroethologist sets them: measured on the per-LED CPU output against numpy, and bad
values refused in one line naming the parameter, the previous scene kept."""

from __future__ import annotations

import math

import numpy as np
import pytest

from antarium.core.pose import Pose
from antarium.renderers.library import build_scene

HOME = Pose(0.0, 0.0, 0.01, 0.0)


def green(frame: np.ndarray, dome) -> np.ndarray:
    """(20350,) green radiance of each LED (gain undone); meaningful on GB pixels."""
    return frame[:, 0] / 65535.0 / dome.gain


def test_a_drum_shows_its_period_contrast_mean_and_drift_at_the_horizon(renderer, dome):
    """Fit mean + a sin(k az) + b cos(k az) to the horizon's GB LEDs: period, Michelson contrast (less the 1.5 deg
    footprint's Gaussian attenuation), mean, and a drift of +speed * t towards larger azimuth (counter-clockwise)."""
    period, speed, contrast, mean = 30.0, 40.0, 0.6, 0.4
    spec = {"scene": "grating", "period_deg": period, "speed_deg_s": speed, "contrast": contrast, "mean": mean,
            "colour": 0.5}  # peak mean * (1 + contrast) * colour = 0.32 a channel: showable
    renderer.set_scene(spec)
    band = ~dome.is_uv & (np.abs(dome.elevation) < math.radians(3))
    k = 2 * np.pi / math.radians(period)
    fit = np.c_[np.ones(band.sum()), np.sin(k * dome.azimuth[band]), np.cos(k * dome.azimuth[band])]
    sigma = math.radians(1.5) / (2 * math.sqrt(2 * math.log(2)))
    attenuation = math.exp(-0.5 * (k * sigma) ** 2)
    colour = spec["colour"]
    for t in (0.0, 0.25):
        c, *_ = np.linalg.lstsq(fit, green(renderer.render(HOME, t=t), dome)[band], rcond=None)
        assert c[0] == pytest.approx(mean * colour, rel=1e-3)
        assert np.hypot(c[1], c[2]) / c[0] == pytest.approx(contrast * attenuation, rel=5e-3)
        # sin(k (az - speed t)): the phase of the fitted wave is -k * speed * t
        shift_deg = -math.degrees(math.atan2(c[2], c[1])) / k
        assert shift_deg == pytest.approx(speed * t, abs=0.02)


def test_a_grating_faster_than_100_turns_a_second_is_refused_and_the_scene_stays(renderer, dome):
    """A speed of 1e308 deg/s was accepted and overflowed the drum's yaw: every LED went dark, without a word."""
    renderer.set_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": 30})
    before = renderer.render(HOME, t=0.5).copy()
    for speed in (1e308, -36_001.0):
        with pytest.raises(ValueError, match=r"^grating speed must be within \+-36000 deg/s"):
            renderer.set_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": speed})
    np.testing.assert_array_equal(renderer.render(HOME, t=0.5), before)
    renderer.set_scene({"scene": "grating", "period_deg": 20, "speed_deg_s": -36_000.0})  # the bound itself


def test_exposure_on_an_integer_panorama_is_refused_not_ignored(renderer, tmp_path):
    """`exposure` scales float (linear) images only; on a PNG it was accepted and did nothing."""
    import cv2

    cv2.imwrite(str(tmp_path / "p.png"), np.full((32, 64, 3), 200, np.uint8))
    renderer.set_scene({"scene": "panorama", "path": str(tmp_path / "p.png")})
    before = renderer.render(HOME).copy()
    with pytest.raises(ValueError, match=r"^panorama exposure scales float \(linear\) images only; .*p\.png is an "
                                         r"integer \(sRGB\) image, so exposure must be 1, got 0\.25"):
        renderer.set_scene({"scene": "panorama", "path": str(tmp_path / "p.png"), "exposure": 0.25})
    np.testing.assert_array_equal(renderer.render(HOME), before)
    cv2.imwrite(str(tmp_path / "uv.tiff"), np.full((32, 64), 0.8, np.float32))  # a float UV layer is scaled
    build_scene({"scene": "panorama", "path": str(tmp_path / "p.png"), "uv": str(tmp_path / "uv.tiff"),
                 "exposure": 0.5})


@pytest.mark.parametrize("spec, message", [
    ({"scene": "habitat", "n_tussocks": 50_001}, "habitat n_tussocks must be an integer in [0, 50,000], got 50001"),
    ({"scene": "habitat", "n_stones": 10_001}, "habitat n_stones must be an integer in [0, 10,000], got 10001"),
    ({"scene": "habitat", "size": 1e9}, "habitat size must be in [20, 10000] m, got 1000000000.0"),
])
def test_habitat_sizes_that_would_never_finish_are_refused_naming_them(spec, message):
    """A billion tussocks ran for ever (a Python loop per tussock); a size of 1e9 m failed on an object's position."""
    with pytest.raises(ValueError) as err:
        build_scene(spec)
    assert str(err.value) == message


@pytest.mark.parametrize("spec, message", [
    ({"scene": "horizon", "elevation_deg": 95}, "horizon elevation must be within (-90, 90) degrees, got 95"),
    ({"scene": "checkerboard", "size_deg": -15}, "checkerboard square size must be in (0, 180] degrees, got -15"),
])
def test_angle_errors_quote_the_degrees_given(spec, message):
    """The horizon's refusal quoted radians ("got 1.6580627893946132 rad") for a value given in degrees."""
    with pytest.raises(ValueError) as err:
        build_scene(spec)
    assert str(err.value) == message
