"""Review checks of the path-integration models against the papers: the CX turns towards home and reaches it
wherever home lies; the sky compass reads the heading from the solar azimuth for several suns in the fixed
tether."""

import math

import numpy as np
import pytest

from antarium.ant.central_complex import CentralComplex, CXParams
from antarium.ant.models import make_model
from antarium.ant.world import virtual_rig


@pytest.mark.parametrize("outbound_deg", [10.0, -110.0])
@pytest.mark.parametrize("home_deg", [45.0, 135.0, -45.0, -135.0])
def test_the_cx_turns_towards_home_and_reaches_it_in_every_quadrant(outbound_deg, home_deg):
    """3 m straight out (noise off), then put down with home `home_deg` off the heading (> 0: to the left, CCW):
    the first motor output turns towards home (> 0 left), and the closed loop (turn = motor) comes within 15 %
    of the feeder distance. A flipped sign anywhere (TN2 halves, CPU4 -> CPU1 offsets, motor) fails one of them."""
    out = math.radians(outbound_deg)
    cx = CentralComplex(CXParams(noise=0.0))
    pos = np.zeros(2)
    for _ in range(300):
        cx.step(out, 0.5)
        pos += 0.01 * np.array([math.cos(out), math.sin(out)])
    feeder = float(np.hypot(*pos))
    heading = out + math.pi - math.radians(home_deg)
    first = None
    closest = feeder
    for _ in range(600):
        motor = cx.step(heading, 0.5)
        first = motor if first is None else first
        heading += float(np.clip(motor, -0.5, 0.5))
        pos += 0.01 * np.array([math.cos(heading), math.sin(heading)])
        closest = min(closest, float(np.hypot(*pos)))
    assert np.sign(first) == np.sign(home_deg) and abs(first) > 0.05, first
    assert closest < 0.15 * feeder, (closest, feeder)


@pytest.mark.parametrize(("sun_azimuth_deg", "sun_elevation_deg"), [(-100.0, 15.0), (170.0, 65.0)])
def test_the_sky_compass_reads_the_heading_from_the_sun_for_several_suns_and_headings(sun_azimuth_deg,
                                                                                       sun_elevation_deg):
    """Fixed tether (the sky turns with the ant): once the polarisers have turned, the heading read is the body
    azimuth relative to the solar azimuth (CCW), within 0.1 deg."""
    scene = {"scene": "sky", "sun_azimuth_deg": sun_azimuth_deg, "sun_elevation_deg": sun_elevation_deg}
    with virtual_rig(make_model("cx", 800, compass="sky"), scene=scene, tether="fixed",
                     renderer_kwargs={"face_size": 64}) as ant:
        for heading_deg in (-150.0, -20.0, 95.0):
            ant.place(0.1, 0.0, math.radians(heading_deg))
            for _ in range(60):
                ant.frame()
            reading = ant.sense().compass
            assert reading.cue, reading.why
            ideal = ant.heading - math.radians(sun_azimuth_deg)
            assert abs(math.degrees(math.remainder(reading.heading - ideal, math.tau))) < 0.1, heading_deg



@pytest.mark.parametrize("bad", [{"noise": math.nan}, {"noise": math.inf}, {"cpu4_gain": math.nan},
                                 {"tb1_slope": math.nan}])
def test_cx_parameters_refuse_values_that_are_not_finite(bad):
    """A NaN noise passed `noise < 0` and left the CX with motor 0 and a decaying memory; a NaN gain emptied it."""
    with pytest.raises(ValueError, match="finite"):
        CXParams(**bad)


@pytest.mark.parametrize("value", [math.nan, -0.1, math.inf])
def test_the_compass_refuses_a_lit_threshold_that_is_negative_or_not_finite(value):
    """min_intensity was not checked: NaN made every sky read "dorsal sky dark", a negative one counted unlit
    pixels as lit."""
    from antarium.ant.compass import CompassParams

    with pytest.raises(ValueError, match="min_intensity"):
        CompassParams(min_intensity=value)


@pytest.mark.parametrize(("extra", "k"), [(np.full(8, 0.9), 0.5), (np.full(16, np.nan), 0.5),
                                          (np.full(16, 0.9), 1.5)])
def test_cpu1_refuses_an_extra_input_it_cannot_use_and_keeps_its_output(extra, k):
    """An (8,) extra input was read past its end by the compiled kernel (CPU1 from whatever lay there), a NaN one
    silenced CPU1 (all 0, motor 0)."""
    cx = CentralComplex(CXParams(noise=0.0))
    cx.compass(0.3)
    before = cx.steering(np.full(16, 0.9), 0.5).copy()
    with pytest.raises(ValueError, match="extra input"):
        cx.steering(extra, k)
    assert np.array_equal(cx.cpu1, before)


@pytest.mark.parametrize("off_deg", [-150.0, -100.0, -60.0, -20.0, 20.0, 60.0, 100.0, 150.0])
def test_the_mbons_alone_steer_towards_the_most_familiar_direction_from_any_heading(off_deg):
    """CXMB's input at CPU1 (eqs. 2-3 laid out as `CXMBModel.mbon_input` lays them, k = 0, noise off): with one
    MBON column most familiar, the motor turns towards that column's direction. It entered uncentred (no Pontine
    counterpart, about 0.875 a column) and turned away from it at 100 and 150 deg off."""
    from antarium.ant.central_complex import N_COLUMNS, PREFS

    column = 2
    responses = np.ones(N_COLUMNS)
    responses[column] = 0.3  # the most familiar: the lowest response
    extra = np.tile(np.roll(1.0 - responses / responses.sum(), N_COLUMNS // 2), 2)
    cx = CentralComplex(CXParams(noise=0.0))
    for _ in range(5):
        cx.compass(PREFS[column] + math.radians(off_deg))
    cx.steering(extra, 0.0)
    assert math.copysign(1.0, cx.motor()) == -math.copysign(1.0, off_deg)  # > 0: left (CCW), towards it
