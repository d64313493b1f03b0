"""Optic-flow collision avoidance on the dome's pixels, the cluttered arena and One Ring, in the emulated dome."""

import math

import numpy as np
import pytest

from antarium.ant.clutter import Clutter, clutter_scene, make_clutter
from antarium.ant.models import make_model
from antarium.ant.optic_flow import FlowParams, OpticFlow
from antarium.ant.world import virtual_rig
from antarium.geometry import load_dome

FACE = 64


@pytest.mark.parametrize("method", ["filter", "foe"])
@pytest.mark.parametrize("heading", [0.0, 2.0])
def test_the_ant_turns_away_from_a_cylinder_on_either_side(method, heading):
    f = np.array([math.cos(heading), math.sin(heading)])
    left = np.array([-math.sin(heading), math.cos(heading)])
    clutter = Clutter(np.array([0.3 * f]), np.array([0.03]))
    flow = OpticFlow.from_dome(load_dome(), FlowParams(method=method))
    with virtual_rig(make_model("cx", 800), scene=clutter_scene(clutter), renderer_kwargs={"face_size": FACE}) as ant:
        for side in (1.0, -1.0):  # the ant 8 cm right of the cylinder's line (cylinder on its left), then left
            ant.place(*(-0.08 * side * left), heading)
            ant.frame()
            before = ant.read_leds().copy()
            turns = []
            for _ in range(3):
                ant.act(0.01, 0.0)
                ant.frame()
                after = ant.read_leds().copy()
                turns.append(flow.avoid(before, after, ant.legs.yaw, 0.01)[0])
                before = after
            assert np.sign(np.mean(turns)) == -side, (side, turns)


def test_no_flow_without_motion_or_obstacles():
    flow = OpticFlow.from_dome(load_dome())
    frame = np.random.default_rng(0).integers(0, 30000, (20350, 2), dtype=np.uint16)
    assert np.allclose(flow.flow(frame, frame), 0.0)
    turn, trace = flow.avoid(frame, frame, 0.0, 0.01)
    assert turn == 0.0 and trace["flow_left"] == trace["flow_right"] == 0.0
    with pytest.raises(ValueError, match="method"):
        FlowParams(method="magic")


def test_clutter_counts_collisions_and_keeps_the_nest_clear():
    clutter = make_clutter(3, n=20, arena_radius=1.0, clear_radius=0.3)
    assert len(clutter.centres) == 20
    assert clutter.clearance([(0.0, 0.0)])[0] >= 0.3 - 0.05
    inside = clutter.centres[0]
    assert clutter.collisions([inside, (0.0, 0.0)]) == 1


def test_arena_trips_run_through_the_dome(tmp_path):
    """A short arena run: outbound with avoidance, CX home (MBONs learn), CXMB and CX from the restored memory;
    every trip home starts from the same state, so the CX-alone trip walks the first one again, noise and all."""
    from antarium.ant.homing import cluttered_arena

    summary = cluttered_arena(tmp_path, seeds=[0], n_outbound=60, n_inbound=60,
                              model_params={"n_kc": 2000}, arena={"n": 8, "arena_radius": 1.0})
    assert summary["runs"] == 1
    assert (tmp_path / "arena_sky_seed00.png").stat().st_size > 10_000
    import json

    outcome = json.loads((tmp_path / "arena_sky.json").read_text())["outcomes"][0]
    assert 0 < outcome["learned_views"] <= 60  # one view per decision of the first homeward trip, to the nest
    assert outcome["closest_cx_share"] == pytest.approx(outcome["closest_cx_again_share"], rel=1e-9)
    assert outcome["outbound_length_m"] == pytest.approx(0.59, abs=0.02)


def test_one_ring_weights_are_checked():
    with pytest.raises(ValueError, match="sum to 1"):
        make_model("one_ring", 800, k_cx=0.9, k_mb=0.2, k_of=0.2)
    for swing in (-0.1, 4.0, float("nan")):
        with pytest.raises(ValueError, match=r"flow_swing must be in \[0, pi\] rad"):
            make_model("one_ring", 800, flow_swing=swing)


@pytest.mark.parametrize("heading", [0.0, 2.0, -2.5])
def test_one_ring_codes_the_avoidance_as_a_heading_on_the_ring(heading):
    """The flow's desired heading: `share` of `flow_swing` off the compass heading, the bump as high as the
    share, peaking opposite (CPU1 steers away from CPU4's vector); flat without flow."""
    from antarium.ant.central_complex import N_COLUMNS, PREFS
    from antarium.ant.navigation import heading_bump

    swing = math.pi / 2
    for share in (1.0, -1.0, 0.5):
        bump = heading_bump(heading + share * swing, abs(share))
        assert np.array_equal(bump[:N_COLUMNS], bump[N_COLUMNS:])
        peak = PREFS[np.argmax(bump[:N_COLUMNS])]
        opposite = heading + share * swing + math.pi
        assert abs(math.remainder(peak - opposite, math.tau)) <= math.pi / N_COLUMNS + 1e-9
        assert bump.max() - bump.min() == pytest.approx(abs(share), abs=0.3)
    assert np.all(heading_bump(heading, 0.0) == 0.5)
