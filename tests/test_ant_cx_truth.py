"""The sky compass and the central-complex experiments tell the truth: no cue while the polarisers still show the
sky before a turn, at the zenith, or (never a flipped heading) beside a cylinder; One Ring reads the optic flow
once a decision; bad parameters, memories, seeds and output folders are refused before anything runs; a seed's
trip does not depend on the seeds before it."""

import math

import numpy as np
import pytest

from antarium.ant.central_complex import CentralComplex
from antarium.ant.clutter import Clutter, clutter_scene
from antarium.ant.homing import displacement, pi_homing
from antarium.ant.models import make_model
from antarium.ant.world import virtual_rig

FACE = 64
SUN_DEG = 135.0


def _rig(scene, tether="free_yaw", model=None):
    return virtual_rig(model or make_model("cx", 800, compass="sky"), scene=scene, tether=tether,
                       renderer_kwargs={"face_size": FACE})


def _readings(ant, headings):
    """After 40 frames, the compass reading one frame after the ant is put down at each of `headings` (rad), in
    turn (a generator: the ant faces that heading while its reading is looked at)."""
    for _ in range(40):
        ant.frame()
    for heading in headings:
        ant.place(0.0, 0.0, heading)
        ant.frame()
        yield ant.sense().compass


def _error_deg(ant, reading, sun_deg):
    return math.degrees(math.remainder(reading.heading + math.radians(sun_deg) - ant.heading, math.tau))


def test_no_cue_while_the_polarisers_still_show_the_sky_before_a_turn():
    """Fixed tether: the scene turns with the ant, the LEDs at once, the polariser actuators over ~0.12 s. The frame
    after a 57 deg turn the e-vectors fit the old sun exactly (residual 0): that reading was -57 deg off with a
    cue. Once the polarisers rest the heading is right again."""
    with _rig({"scene": "sky", "sun_azimuth_deg": SUN_DEG}, tether="fixed") as ant:
        for _ in range(40):
            ant.frame()
        ant.place(0.0, 0.0, 1.0)
        ant.frame()
        turning = ant.sense().compass
        assert not turning.cue and math.isnan(turning.heading)
        assert "polarisers turning" in turning.why
        for _ in range(60):
            ant.frame()
        settled = ant.sense().compass
        assert settled.cue, settled.why
        assert abs(_error_deg(ant, settled, SUN_DEG)) < 0.5


def test_in_the_fixed_tether_an_ant_that_waits_for_its_cue_walks_on_a_true_compass():
    """Without waiting, a foraging trip in the fixed tether ends at its first decision (no cue while the polarisers
    turn after the scene turned); an ant that stands still until the cue is back (`cue_wait_frames`) walks the
    whole trip, every decision's compass within 1 deg of its true heading (0.61 deg at most here)."""
    from antarium.ant.homing import pi_trial, settle

    for wait in (0, 60):
        with virtual_rig(make_model("cx", 800, compass="sky"), scene={"scene": "sky", "sun_azimuth_deg": SUN_DEG},
                         tether="fixed", renderer_kwargs={"face_size": FACE}, cue_wait_frames=wait) as ant:
            settle(ant)
            metrics, outbound, inbound = pi_trial(ant, 0, 30, 30)
            if wait == 0:
                assert metrics["lost_cue"].startswith("outbound, decision 0: the sky compass has no cue")
                assert ant.cue_waits == 0
                continue
            assert metrics["lost_cue"] is None and ant.cue_waits > 0
            assert len(outbound.traces) == 29 and len(inbound.traces) == 30
            read = np.array([t["compass"] for t in outbound.traces + inbound.traces])
            true = np.concatenate([outbound.heading, inbound.heading])
            error = np.degrees(np.remainder(read + math.radians(SUN_DEG) - true + math.pi, math.tau) - math.pi)
            assert np.abs(error).max() < 1.0


@pytest.mark.parametrize("elevation_deg", [5.0, -5.0, 89.5])
def test_settled_skies_keep_their_cue_at_every_heading(elevation_deg):
    with _rig({"scene": "sky", "sun_azimuth_deg": SUN_DEG, "sun_elevation_deg": elevation_deg}) as ant:
        for reading in _readings(ant, (-2.0, 0.0, 1.0, 2.5)):
            assert reading.cue, reading.why
            assert abs(_error_deg(ant, reading, SUN_DEG)) < 0.5


def test_a_sun_at_the_zenith_gives_no_cue():
    """No solar azimuth: the fit's horizontal part is rounding, and the heading was +-45 deg off with a cue."""
    with _rig({"scene": "sky", "sun_azimuth_deg": SUN_DEG, "sun_elevation_deg": 90.0}) as ant:
        for reading in _readings(ant, (0.0, 1.0)):
            assert not reading.cue and "zenith" in reading.why


def test_a_cylinder_towards_the_sun_does_not_flip_the_heading():
    """A cylinder (radius 5 cm) 1 cm from the ant towards the sun hides the brightest dorsal pixels: summed over
    every pixel the brightness pointed to the anti-sun, and the heading read 180 deg off with a cue."""
    cylinder = Clutter(np.array([[0.06, 0.0]]), np.array([0.05]), 0.1)
    with _rig(clutter_scene(cylinder, {"sun_azimuth_deg": 0.0})) as ant:
        ant.place(0.0, 0.0, 0.0)
        for reading in _readings(ant, (0.0, 1.5)):
            assert reading.cue, reading.why
            assert abs(_error_deg(ant, reading, 0.0)) < 0.5


def test_one_ring_reads_the_optic_flow_once_a_decision_and_keeps_its_trace():
    model = make_model("one_ring", 800, compass="ideal", avoid=True, n_kc=2000)
    turns = []
    avoidance = model.avoidance

    def counted(senses):
        turn, trace = avoidance(senses)
        turns.append(turn)
        return turn, trace

    model.avoidance = counted
    cylinder = Clutter(np.array([[0.12, 0.05]]), np.array([0.02]), 0.1)
    with virtual_rig(model, scene=clutter_scene(cylinder), renderer_kwargs={"face_size": FACE},
                     compass="ideal") as ant:
        for _ in range(5):
            ant.frame()
        ant.place(0.0, 0.0, 0.0)
        ant.frame()
        ant.sense()
        for _ in range(3):
            turns.clear()
            cmd = ant.decide()
            assert len(turns) == 1
            assert cmd.trace["flow_turn"] == turns[0]
    assert cmd.trace["flow_turn"] != 0.0  # the cylinder's flow, not a second read that saw none


@pytest.mark.parametrize("params", [{"flow_gain": 0.0}, {"flow_gain": -0.1}, {"flow_method": "bogus"}])
def test_optic_flow_parameters_are_checked_when_the_model_is_made(params):
    with pytest.raises(ValueError, match=r"CX flow_method must be one of filter, foe and flow_gain > 0 rad"):
        make_model("one_ring", 800, n_kc=100, **params)


def test_a_cpu4_memory_outside_0_1_is_refused_and_the_memory_kept():
    cx = CentralComplex()
    before = cx.memory()
    for bad in (np.full(16, 1.5), np.full(16, -0.1), np.full(16, np.nan)):
        with pytest.raises(ValueError, match=r"CPU4 memory must be \(16,\) rates in \[0, 1\]"):
            cx.restore(bad)
        np.testing.assert_array_equal(cx.memory(), before)
    cx.restore(np.full(16, 0.25))
    np.testing.assert_array_equal(cx.memory(), np.full(16, 0.25))


def test_homing_and_displace_find_an_unwritable_folder_before_they_run(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    echoed = []
    with pytest.raises(OSError):
        pi_homing(blocker / "out", seeds=[0], n_outbound=3, compass="ideal", echo=echoed.append)
    with pytest.raises(OSError):
        displacement(blocker / "out", n_outbound=3, ks=(1.0,), compass="ideal", scene="sky", echo=echoed.append)
    assert echoed == []  # nothing ran


def test_displace_names_a_negative_seed(tmp_path, capsys):
    from antarium.cli import main

    assert main(["ant", "displace", "--seed", "-1", "--out", str(tmp_path)]) != 0
    assert "--seed >= 0, got 600 and -1" in capsys.readouterr().err


def test_compiled_degree_check_equals_the_straightforward_numpy():
    from antarium.ant.compass import SkyCompass
    from antarium.ant.cx_kernels import degree_excess
    from antarium.bench.ant_cx import sky_frames
    from antarium.geometry import load_dome

    dome = load_dome()
    compass = SkyCompass.from_dome(dome)
    frames, _ = sky_frames(dome, 2)
    for f in frames:
        for sun in (np.array([-0.5, 0.5, math.sqrt(0.5)]), np.array([0.0, -1.0, 0.0])):
            light = f[compass.pixels].astype(np.float64) * compass._scale[:, None]
            total = light.sum(axis=1)
            sky = (total > 0.01) & (light[:, 1] >= 0.05 * total)
            c = compass._dirs[sky] @ sun
            q = (1 - c * c) / (1 + c * c)
            p = light[sky, 1] / total[sky]
            p_max = np.median(p[q >= 0.3] / q[q >= 0.3])
            expected = np.sqrt(np.mean(np.maximum(0.0, p - p_max * q) ** 2)) / p_max
            assert degree_excess(f, compass.pixels, compass._scale, compass._dirs, sun, 0.01, 0.05) == \
                pytest.approx(expected, rel=1e-12)
