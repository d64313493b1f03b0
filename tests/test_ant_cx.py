"""Stone 2017's central complex: the memory integrates the walk, CPU1 steers home, vector memory is kept; and the
virtual ant homes by it in the emulated dome with the compass read from the sky."""

import math

import numpy as np
import pytest

from antarium.ant.central_complex import CentralComplex, CXParams
from antarium.ant.homing import Trip, homing_metrics, pi_homing


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
