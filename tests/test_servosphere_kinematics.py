"""Servosphere kinematics (Goulard et al. 2021, Eqs. 2-6), the PD controller and the steppers' limits."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.locomotion.servosphere.controller import Controller, ControllerConfig
from antarium.locomotion.servosphere.kinematics import RotorGeometry, StepperLimits, inverse_eq6, rotor_matrix

_angle = st.floats(-180, 180)
_elev = st.floats(15, 75)


@settings(max_examples=60, deadline=None)
@given(az=st.tuples(_angle, _angle, _angle), el=st.tuples(_elev, _elev, _elev),
       omega=st.tuples(*[st.floats(-20, 20)] * 3), rw=st.floats(0.005, 0.05), rs=st.floats(0.02, 0.2))
def test_eq4_and_its_inverse_round_trip(az, el, omega, rw, rs):
    m = rotor_matrix(az, el)
    if abs(np.linalg.det(m)) < 1e-2:  # nearly coplanar axes are refused (tested below)
        return
    geo = RotorGeometry(az, el, rw, rs)
    motor = geo.motor_speeds(omega)
    tolerance = 1e-6 * (1 + max(map(abs, omega))) / abs(np.linalg.det(m))  # rad/s; conditioning of RMat
    assert geo.sphere_omega(motor) == pytest.approx(omega, abs=tolerance)


def test_eq6_cofactor_inverse_is_the_matrix_inverse():
    m = rotor_matrix((0, 120, 240), (60, 60, 60))
    assert inverse_eq6(m) @ m == pytest.approx(np.eye(3), abs=1e-12)


def test_paper_rig_axes_and_a_pure_roll():
    geo = RotorGeometry()
    assert geo.rmat[:, 0] == pytest.approx([0.5, 0.0, math.sqrt(3) / 2])  # azimuth 0, elevation 60 deg
    assert np.linalg.norm(geo.rmat, axis=0) == pytest.approx(np.ones(3))
    # a yaw turns the three rotors equally; a roll about y leaves rotor 1 (axis in the x-z plane) still
    yaw = geo.motor_speeds([0, 0, 1.0])
    assert yaw == pytest.approx(np.full(3, yaw[0])) and yaw[0] > 0
    roll_y = geo.motor_speeds([0, 1.0, 0])
    assert roll_y[0] == pytest.approx(0.0, abs=1e-12) and roll_y[1] == pytest.approx(-roll_y[2])


def test_omniwheel_contact_model_each_wheel_sees_only_its_own_axis():
    """R_s (omega . a_i) = R_w M_i: turning wheel 1 alone asks no surface speed of the locked wheels 2 and 3 along
    their drive directions (the paper's Eq. 4 would: omega = (0.25, 0, 0.433) at the rig's 60 deg axes)."""
    geo = RotorGeometry()
    omega = geo.sphere_omega([1.0, 0.0, 0.0])
    assert omega == pytest.approx([2 / 3, 0.0, 1 / (3 * math.sqrt(3))], abs=1e-12)  # (0.667, 0, 0.192) rad/s
    surface = geo.sphere_radius * (geo.rmat.T @ omega)  # m/s along each wheel's drive direction
    assert surface == pytest.approx([geo.wheel_radius, 0.0, 0.0], abs=1e-12)
    # and the motor speeds for a roll are the ball's rotation about each axis, scaled
    omega = np.array([0.3, -1.0, 0.2])
    assert geo.motor_speeds(omega) == pytest.approx(geo.rmat.T @ omega * geo.sphere_radius / geo.wheel_radius)


def test_contact_model_is_eq4_for_orthogonal_axes():
    el = math.degrees(math.atan(1 / math.sqrt(2)))  # 35.26 deg: axes 120 deg apart in azimuth are orthogonal
    geo = RotorGeometry(elevation_deg=(el, el, el))
    assert geo.rmat.T @ geo.rmat == pytest.approx(np.eye(3), abs=1e-12)
    eq4 = geo.rmat * (geo.wheel_radius / geo.sphere_radius)
    assert geo.to_sphere == pytest.approx(eq4, abs=1e-12)
    assert geo.to_motor == pytest.approx(np.linalg.inv(eq4), abs=1e-12)


def test_coplanar_rotors_are_refused_with_what_is_allowed():
    with pytest.raises(ValueError, match="coplanar.*allowed"):
        RotorGeometry(elevation_deg=(0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="3 rotor azimuths"):
        rotor_matrix((0, 120), (60, 60))


def test_stepper_limits_clip_rate_and_acceleration():
    lim = StepperLimits(steps_per_rev=200, max_rate=1000.0, max_accel=10000.0)
    out = lim.limit(np.array([5000.0, -5000.0, 10.0]), np.zeros(3), 0.01)
    assert out == pytest.approx([100.0, -100.0, 10.0])
    assert lim.limit(np.array([5000.0, 0, 0]), np.array([995.0, 0, 0]), 0.01)[0] == pytest.approx(1000.0)
    with pytest.raises(ValueError, match="max_rate"):
        StepperLimits(max_rate=0.0)


def test_pd_moves_the_apex_surface_toward_the_ant():
    ctl = Controller(ControllerConfig(kd=0.0))
    ctl.update((2.0, -1.0), math.nan, 0.01)
    wx, wy, wz = ctl.omega
    # surface velocity at the apex is (wy R, -wx R): it must point from the ant back to the apex (-2, +1)
    assert wy == pytest.approx(-2.5) and -wx == pytest.approx(1.25) and wz == 0.0


def test_pd_derivative_and_stop_on_no_measurement():
    cfg = ControllerConfig(kp=0.0, kd=0.01)
    ctl = Controller(cfg)
    ctl.update((0.0, 0.0), 0.0, 0.001)
    ctl.update((0.1, 0.0), 0.0, 0.001)  # 100 mm/s
    assert ctl.omega[1] == pytest.approx(-1.0)
    rates = ctl.rates.copy()
    ctl.update(None, 0.0, 0.001)
    assert not ctl.omega.any()
    assert np.all(np.abs(ctl.rates) <= np.abs(rates))  # ramping toward 0 at the acceleration limit


def test_counter_rotation_turns_the_ball_against_the_ant():
    ctl = Controller(ControllerConfig(counter_rotate=True, kp_yaw=2.0))
    ctl.update((0.0, 0.0), math.radians(30), 0.001)
    assert ctl.omega[2] == pytest.approx(-2.0 * math.radians(30))
    with pytest.raises(ValueError, match="kp must be"):
        ControllerConfig(kp=-1.0)


@pytest.mark.parametrize("setting, value", [("azimuth_deg", (0.0, 120.0, math.nan)),
                                            ("elevation_deg", (60.0, math.inf, 60.0))])
def test_non_finite_rotor_angles_are_refused(setting, value):
    with pytest.raises(ValueError, match=f"rotor geometry {setting} must be 3 finite angles"):
        RotorGeometry(**{setting: value})
