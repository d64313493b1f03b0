"""Ball kinematics: design matrix, least-squares solve, slip residual, motion of the ant on the top pole."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.core.ball import pole_motion
from antarium.locomotion.trackball.kinematics import DEFAULT_SENSORS, BallSolver, SensorPlacement, design_matrix

R = 0.05
angles = st.floats(-math.pi, math.pi, allow_nan=False)
small = st.floats(-0.1, 0.1, allow_nan=False)


def test_default_placement_reads_yaw_twice_and_one_tilt_each():
    # sensor 0 at the front reads R*wz (x) and -R*wy (y); sensor 1 at the left reads R*wz and R*wx
    A = design_matrix(DEFAULT_SENSORS, R)
    expected = R * np.array([[0, 0, 1], [0, -1, 0], [0, 0, 1], [1, 0, 0]], dtype=float)
    np.testing.assert_allclose(A, expected, atol=1e-15)


def test_sensor_axes_are_tangent_and_orthonormal():
    s = SensorPlacement(0.3, -0.4, 0.7)
    p, axes = s.position(), s.axes()
    np.testing.assert_allclose(axes @ p, 0.0, atol=1e-15)
    np.testing.assert_allclose(axes @ axes.T, np.eye(2), atol=1e-15)


@settings(max_examples=300, deadline=None)
@given(a0=angles, e0=angles, r0=angles, a1=angles, e1=angles, r1=angles, w=st.tuples(small, small, small))
def test_solve_inverts_forward_model_for_any_resolving_placement(a0, e0, r0, a1, e1, r1, w):
    sensors = (SensorPlacement(a0, e0 / 2, r0), SensorPlacement(a1, e1 / 2, r1))
    try:
        solver = BallSolver(sensors, R)
    except ValueError:
        return  # a placement that cannot see all three axes is rejected with a clear error (tested below)
    if np.linalg.cond(solver.matrix) > 1e6:
        return
    m = solver.readings(np.array(w))
    r, res = solver.solve(m)
    np.testing.assert_allclose(r, w, atol=1e-9)
    assert res < 1e-12
    rot, q = solver.solve_one(list(m))
    np.testing.assert_allclose(rot, w, atol=1e-9)
    assert q == pytest.approx(1.0)


def test_degenerate_placement_is_rejected():
    with pytest.raises(ValueError, match="rank"):
        BallSolver((SensorPlacement(0.0), SensorPlacement(0.0)), R)


def test_slip_gives_residual_and_lower_quality():
    solver = BallSolver(radius=R)
    m = solver.readings(np.array([0.0, -0.02, 0.01]))
    slipped = m.copy()
    slipped[2] = 0.0  # sensor 1 lifted: its yaw reading disagrees with sensor 0's
    _, res = solver.solve(slipped)
    assert res == pytest.approx(abs(m[2]) / math.sqrt(2), rel=1e-9)  # one redundant reading: half the misfit each
    _, q = solver.solve_one(list(slipped))
    assert 0.0 < q < 0.9
    assert solver.quality(m, solver.solve(m)[1]) == pytest.approx(1.0)


def test_vectorised_and_scalar_paths_agree():
    solver = BallSolver(radius=R)
    rng = np.random.default_rng(1)
    m = rng.normal(size=(50, 4)) * 1e-3
    r, res = solver.solve(m)
    q = solver.quality(m, res)
    for i in range(50):
        rot, qi = solver.solve_one(list(m[i]))
        np.testing.assert_allclose(rot, r[i], atol=1e-15)
        assert qi == pytest.approx(q[i])


def test_ant_walking_forward_left_and_turning_on_the_top_pole():
    """Forward walking turns the ball about -y; pole_motion returns the ant's own motion (both tether modes)."""
    solver = BallSolver(radius=R)
    v, side, yaw = 0.01, 0.004, 0.2  # m, m, rad in one increment
    ball = np.array([side / R, -v / R, -yaw])  # the ball turns opposite to the ant
    rotation, _ = solver.solve_one(list(solver.readings(ball)))
    dx, dy, dyaw = pole_motion(rotation, R)
    assert (dx, dy) == pytest.approx((v, side))
    # fixed tether: the ant cannot turn, so the ball's yaw is the ant's intended turn
    assert dyaw == pytest.approx(yaw)
    # free-yaw tether: the ant turns itself and the ball shows (almost) no yaw; translation is still read
    free, _ = solver.solve_one(list(solver.readings(np.array([side / R, -v / R, 0.0]))))
    assert pole_motion(free, R) == pytest.approx((v, side, 0.0))
