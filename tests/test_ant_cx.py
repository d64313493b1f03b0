"""Stone 2017's central complex: the memory integrates the walk, CPU1 steers home, vector memory is kept; and the
virtual ant homes by it in the emulated dome with the compass read from the sky."""

import math

import numpy as np
import pytest

from antarium.ant.central_complex import CentralComplex, CXParams
from antarium.ant.homing import Trip, cluttered_arena, displacement, homing_metrics, pi_homing


def _walk(cx, heading, n, speed=0.5):
    for _ in range(n):
        cx.step(heading, speed)


@pytest.mark.parametrize("heading", [0.0, 1.0, -2.5])
def test_memory_points_along_the_outbound_walk(heading):
    cx = CentralComplex(CXParams(noise=0.0))
    _walk(cx, heading, 200)
    direction, strength = cx.home_vector()
    assert abs(math.remainder(direction - heading, math.tau)) < math.radians(15)  # 8 columns: 45 deg apart
    assert strength > 0.1


def test_cpu1_turns_towards_home_from_either_side():
    cx = CentralComplex(CXParams(noise=0.0))
    _walk(cx, 0.0, 200)  # home lies at pi
    memory = cx.memory()
    # motor > 0: turn left (CCW). Facing clockwise of home (pi - 0.4, pi / 2) it turns left, else right.
    for heading, left in ((math.pi - 0.4, True), (math.pi / 2, True), (-math.pi + 0.4, False), (-math.pi / 2, False)):
        cx.restore(memory)
        for _ in range(3):
            cx.compass(heading)
        cx.steering()
        assert (cx.motor() > 0.02) if left else (cx.motor() < -0.02), (heading, cx.motor())


def test_vector_memory_is_stored_and_restored():
    cx = CentralComplex(CXParams(noise=0.0))
    _walk(cx, 0.7, 150)
    stored = cx.memory()
    _walk(cx, -2.0, 150)
    assert not np.allclose(cx.memory(), stored)
    cx.restore(stored)
    assert np.allclose(cx.memory(), stored)
    with pytest.raises(ValueError, match="CPU4 memory"):
        cx.restore(np.zeros(8))


def test_leak_pulls_the_memory_back_to_rest():
    cx = CentralComplex(CXParams(noise=0.0, leak=0.05))
    _walk(cx, 0.0, 200)
    _, strength = cx.home_vector()
    _walk(cx, 0.0, 200, speed=0.0)
    assert cx.home_vector()[1] < 0.2 * strength


def test_parameters_are_checked():
    with pytest.raises(ValueError, match="leak"):
        CXParams(leak=1.5)


@pytest.mark.parametrize("compass", ["sky", "ideal"])
def test_the_virtual_ant_homes_by_path_integration_in_the_dome(compass, tmp_path):
    """A short trip (2.5 m out): the benchmark's goal is 5 % over 1,500-step routes; short ones are noisier."""
    summary = pi_homing(tmp_path, seeds=[3], n_outbound=250, n_inbound=400, compass=compass)
    assert summary["runs"] == 1
    assert summary["closest_approach_share_median"] < 0.10
    assert (tmp_path / f"pi_homing_{compass}_paths.png").stat().st_size > 10_000


def test_homing_metrics_of_a_straight_return():
    out = Trip(np.array([[1.0, 0.0], [2.0, 0.0]]), np.zeros(2), [])
    home = Trip(np.array([[1.0, 0.0], [0.1, 0.0], [0.3, 0.0]]), np.full(3, math.pi), [])
    m = homing_metrics(out, home)
    assert m["outbound_length_m"] == pytest.approx(2.0)
    assert m["closest_approach_m"] == pytest.approx(0.1)
    assert m["tortuosity"] == pytest.approx(1.9 / 1.9)


def _line(x0: float, dx: float, n: int) -> Trip:
    return Trip.walked([(x0 + i * dx, 0.0) for i in range(1, n + 1)], [0.0] * n, [{}] * n)


def test_tortuosity_is_path_length_over_the_approach_and_nan_when_the_ant_never_came_nearer():
    out = _line(0.0, 0.01, 100)  # 1 m straight out
    away = homing_metrics(out, _line(1.0, 0.01, 100))
    assert away["closest_approach_m"] == pytest.approx(1.0) and math.isnan(away["tortuosity"])
    assert math.isnan(homing_metrics(out, Trip.walked([], [], []))["tortuosity"])  # lost its cue at once
    half = Trip.walked([(1.0 - i * 0.01, 0.0) for i in range(1, 51)] + [(0.5, 0.0)] * 50, [math.pi] * 100, [{}] * 100)
    assert homing_metrics(out, half)["tortuosity"] == pytest.approx(0.5 / 0.5)
    # 0.4 m sideways, then 1 m toward the nest: L = 1.4 m, C = 1 - hypot(0, 0.4) m
    zigzag = Trip.walked([(1.0, 0.1 * i) for i in range(1, 5)] + [(1.0 - 0.1 * i, 0.4) for i in range(1, 11)],
                         [0.0] * 14, [{}] * 14)
    assert homing_metrics(out, zigzag)["tortuosity"] == pytest.approx(1.4 / (1.0 - 0.4))


@pytest.mark.parametrize("kind", ["cx", "cxmb", "one_ring"])
def test_central_complex_models_round_trip_through_model_files(kind, tmp_path):
    from antarium.ant.eye import EyeParams
    from antarium.ant.models import make_model
    from antarium.ant.storage import load_model, save_model

    model = make_model(kind, 800, noise=0.0, **({} if kind == "cx" else {"n_kc": 2000}))
    for _ in range(50):
        model.cx.step(0.4, 0.5)
    path = save_model(tmp_path / f"{kind}.npz", model, EyeParams())
    back, _, _ = load_model(path)
    assert back.kind == kind and back.params == model.params
    assert np.array_equal(back.cx.memory(), model.cx.memory())


def test_a_trip_ends_where_a_tall_object_hides_the_sky_and_keeps_what_it_walked():
    """Home through a 20 m tower: inside it the dorsal rim sees no sky, so the compass has no cue. The trip stops
    there and says so; its metrics cover the decisions walked until then."""
    from antarium.ant.clutter import Clutter, clutter_scene
    from antarium.ant.eye import EyeParams
    from antarium.ant.homing import walk_home, walk_outbound
    from antarium.ant.models import make_model
    from antarium.ant.world import virtual_rig

    tower = Clutter(np.array([[0.45, 0.2]]), np.array([0.15]), height=20.0)
    model = make_model("cx", EyeParams().n_pn, compass="sky", noise=0.0)
    with virtual_rig(model, scene=clutter_scene(tower), renderer_kwargs={"face_size": 64}) as ant:
        for _ in range(40):
            ant.frame()
        turns = np.zeros(150)
        turns[0], turns[50] = math.pi / 2, -math.pi / 2  # 0.5 m north, then 1 m east: the tower lies on the way home
        out = walk_outbound(ant, turns, 0.01)
        home = walk_home(ant, 150)
    assert out.lost_cue is None and len(out.xy) == 149
    assert home.lost_cue is not None and "no cue" in home.lost_cue and "depolarised" in home.lost_cue
    assert 0 < len(home.xy) == len(home.traces) < 150
    assert home.lost_cue.startswith(f"decision {len(home.xy)}:")
    assert tower.clearance(home.xy[-1])[0] < 0.011  # it stopped inside the tower or within a 1 cm step of it
    m = homing_metrics(out, home)
    assert m["closest_approach_m"] == pytest.approx(np.hypot(*home.xy.T).min())


def test_a_learning_trip_home_learns_until_the_ant_reaches_the_nest_and_not_in_its_search_after():
    """The MBONs learn the inbound route: every decision until the ant first comes within NEST_RADIUS of the nest,
    none of the loops it walks around the nest after (views facing every way)."""
    from antarium.ant.eye import EyeParams
    from antarium.ant.homing import NEST_RADIUS, walk_home, walk_outbound
    from antarium.ant.models import make_model
    from antarium.ant.world import virtual_rig

    model = make_model("cxmb", EyeParams().n_pn, compass="ideal", n_kc=2000, noise=0.0)
    with virtual_rig(model, scene="sky", renderer_kwargs={"face_size": 64}, compass="ideal") as ant:
        for _ in range(40):
            ant.frame()
        walk_outbound(ant, np.r_[0.3, np.zeros(299)], 0.01)  # 3 m out, straight
        home = walk_home(ant, 600, learning=True)
    near = np.flatnonzero(np.hypot(*home.xy.T) < NEST_RADIUS)
    assert home.lost_cue is None and len(near) and 0 < near[0] < 550  # it came home, with decisions to spare
    assert model.learned_views == near[0] + 1
    assert model.learning is False


def test_arena_and_foraging_runs_go_on_after_a_trip_without_a_compass_cue(tmp_path):
    """A depolarised sky: every outbound loses its cue at once. Each seed is recorded with why, and the run goes
    on to the next seed and writes strict JSON (null for what was not measured)."""
    import json

    from antarium.ant.homing import cluttered_arena

    summary = cluttered_arena(tmp_path, seeds=[0, 1], n_outbound=10, sky={"dop_max": 0.0},
                              model_params={"n_kc": 2000}, arena={"n": 4, "arena_radius": 1.0})
    assert summary["runs"] == 2
    assert set(summary["trips_without_cue"]) == {"seed 0", "seed 1"}
    assert all("depolarised" in lost["outbound"] for lost in summary["trips_without_cue"].values())
    record = json.loads((tmp_path / "arena_sky.json").read_text())
    assert record["summary"]["closest_cxmb_share_median"] is None
    assert (tmp_path / "arena_sky_seed01.png").stat().st_size > 10_000
    homing = pi_homing(tmp_path, seeds=[0, 1], n_outbound=10, scene={"scene": "sky", "dop_max": 0.0})
    assert homing["runs"] == 2 and set(homing["runs_without_cue"]) == {"seed 0", "seed 1"}
    assert math.isnan(homing["closest_approach_share_median"])


@pytest.mark.parametrize("compass", ["ideal", "sky"])
def test_a_seeds_foraging_trip_does_not_depend_on_the_seeds_before_it(monkeypatch, compass):
    """Bit for bit, with either compass: the experiment lets the polarisers come to rest first (with the sky
    compass they still crept by ~1e-5 rad after a fixed 40 frames, and a trip after another started from a dome
    more at rest: 8e-8 m apart after 200 steps, until 2026-11-27)."""
    from antarium.ant import homing

    ends: dict[int, list] = {}
    trial = homing.pi_trial

    def spy(ant, seed, n_outbound, n_inbound):
        metrics, out, home = trial(ant, seed, n_outbound, n_inbound)
        ends.setdefault(seed, []).append(np.vstack([out.xy, home.xy]))
        return metrics, out, home

    monkeypatch.setattr(homing, "pi_trial", spy)
    pi_homing(None, seeds=[1], n_outbound=60, n_inbound=60, compass=compass)
    pi_homing(None, seeds=[0, 1], n_outbound=60, n_inbound=60, compass=compass)
    alone, after_seed_0 = ends[1]
    assert alone.shape == (119, 2)
    np.testing.assert_array_equal(alone, after_seed_0)
    assert not np.array_equal(ends[0][0][:59], alone[:59])  # another route


def test_one_ring_refuses_cxmbs_k_which_it_does_not_use():
    from antarium.ant.models import make_model
    from antarium.ant.navigation import OneRingParams

    with pytest.raises(ValueError, match=r"One Ring does not use CXMB's k \(got 0.3; allowed: its default 0.8\); "
                                         r"weigh CPU4, the MBONs and the optic flow with k_cx, k_mb, k_of"):
        make_model("one_ring", 800, k=0.3, n_kc=100)
    assert OneRingParams().k == 0.8  # the default stays valid (files and make_model without k)
    assert make_model("one_ring", 800, k_cx=0.5, k_mb=0.3, k_of=0.2, n_kc=100).params.k_mb == 0.3
    assert make_model("cxmb", 800, k=0.3, n_kc=100).params.k == 0.3


@pytest.mark.parametrize("task", [pi_homing, cluttered_arena, displacement])
def test_the_tasks_refuse_trip_lengths_they_cannot_walk_before_anything_runs(task, tmp_path):
    """An inbound trip of 0 decisions is refused (it was read as "as long as the outbound trip", `n or default`),
    and so are an outbound trip shorter than 2 decisions and a non-integer count; nothing is written."""
    for n_outbound, n_inbound, message in ((10, 0, "inbound decisions must be an integer >= 1, got 0"),
                                           (1, None, "outbound decisions must be an integer >= 2, got 1"),
                                           (10, 2.5, "inbound decisions must be an integer >= 1, got 2.5")):
        which = {"seed": 0} if task is displacement else {"seeds": [0]}
        with pytest.raises(ValueError) as err:
            task(tmp_path, n_outbound=n_outbound, n_inbound=n_inbound, **which)
        assert str(err.value) == message
    assert list(tmp_path.iterdir()) == []
