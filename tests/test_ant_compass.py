"""The virtual ant's sky compass reads the emulated dome (renderer -> frame loop -> virtual link -> panels and
polarisers), and says so when there is no polarised sky."""

import math

import numpy as np
import pytest

from antarium.ant.compass import CompassParams, NoSkyCueError, SkyCompass, e_vectors_from_polarisers
from antarium.ant.models import make_model
from antarium.ant.world import virtual_rig
from antarium.geometry import load_dome

FACE = 64
SUN_DEG = 135.0
#: the compass's error over a full turn, once the polarisers have reached the sky's e-vectors
MAX_ERROR_DEG = 3.0


def _rig(scene, compass="sky"):
    return virtual_rig(make_model("cx", 800, compass=compass), scene=scene, renderer_kwargs={"face_size": FACE})


def _settle(ant, frames=40):
    for _ in range(frames):
        ant.frame()


def test_sky_compass_follows_a_full_turn_within_3_degrees():
    scene = {"scene": "sky", "sun_azimuth_deg": SUN_DEG}
    with _rig(scene) as ant:
        _settle(ant)
        errors = []
        for k in range(24):
            heading = -math.pi + k * math.tau / 24
            ant.place(0.2, -0.1, heading)
            ant.frame()
            reading = ant.sense().compass
            assert reading.cue, reading.why
            # the sky compass's zero is the sun's azimuth
            errors.append(math.remainder(reading.heading + math.radians(SUN_DEG) - ant.heading, math.tau))
    assert np.degrees(np.max(np.abs(errors))) < MAX_ERROR_DEG


@pytest.mark.parametrize("scene", [{"scene": "sky", "dop_max": 0.0}, {"scene": "uniform", "colour": 0.5}])
def test_compass_reports_no_cue_without_a_polarised_sky_and_the_cx_fails_loudly(scene):
    with _rig(scene) as ant:
        _settle(ant)
        reading = ant.sense().compass
        assert not reading.cue and math.isnan(reading.heading)
        assert "depolarised" in reading.why or "dark" in reading.why
        with pytest.raises(NoSkyCueError, match="no cue"):
            ant.decide()


def test_compass_refuses_e_vectors_that_no_sun_explains():
    dome = load_dome()
    compass = SkyCompass.from_dome(dome)
    leds = np.zeros((dome.directions.shape[0], 2), np.uint16)
    leds[dome.uv_index] = (20000, 10000)  # lit and 33 % polarised...
    angles = np.random.default_rng(0).uniform(0, np.pi, (55, 9))  # ...but e-vectors at random
    reading = compass.read(leds, angles)
    assert not reading.cue and "fit no sun" in reading.why
    with pytest.raises(NoSkyCueError):
        compass.heading(leds, angles)


def test_e_vectors_invert_the_renderers_polariser_angles():
    from antarium.renderers.output import polariser_angles

    dome = load_dome()
    uv = dome.uv_index
    d = np.asarray(dome.directions)[uv]
    axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
    rng = np.random.default_rng(1)
    e = np.cross(d, rng.normal(size=d.shape))
    e /= np.linalg.norm(e, axis=1, keepdims=True)
    back = e_vectors_from_polarisers(d, polariser_angles(d, e, axes), axes)
    assert np.allclose(np.abs(np.einsum("ij,ij->i", back, e)), 1.0, atol=1e-9)


def test_compass_parameters_are_checked():
    with pytest.raises(ValueError, match="min_pixels"):
        CompassParams(min_pixels=1)
    with pytest.raises(ValueError, match="compass"):
        make_model("cx", 800, compass="magnetic")
