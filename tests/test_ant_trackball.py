"""The virtual ant walks through the emulated USB trackball, read by the real driver (pyusb code path), in both
tether modes: on the loop's SimulatedClock (faster than real time, reproducible) and on a MonotonicClock."""

import math

import numpy as np
import pytest

from antarium.ant.agent import follow_route, learning_walk
from antarium.ant.locomotion import AntLocomotion, Strides, TrackballLegs
from antarium.ant.models import make_model
from antarium.ant.route_following import MODEL_EYES, MODEL_PARAMS
from antarium.ant.routes import curved_route
from antarium.ant.world import virtual_rig
from antarium.core.clock import MonotonicClock, SimulatedClock
from antarium.core.pose import Pose
from antarium.locomotion.trackball.emulator import EmulatedTrackball
from antarium.server.frame_loop import FrameLoop
from antarium.trial_log import read_table

FACE = 64
ROUTE = curved_route(4, length=0.6, start=(0.5, -0.3))


def test_strides_integrate_piecewise_constant_steps_exactly():
    strides = Strides()
    strides.add(0.0, 0.01, (0.0, -1.0, 0.5))
    strides.add(0.01, 0.02, (1.0, 0.0, 0.0))
    assert strides.rotation(0.0, 0.005) == pytest.approx((0.0, -0.5, 0.25))
    assert strides.rotation(0.005, 0.015) == pytest.approx((0.5, -0.5, 0.25))
    assert strides.rotation(0.015, 1.0) == pytest.approx((0.5, 0.0, 0.0))
    strides.clear()
    assert strides.rotation(0.0, 1.0) == (0.0, 0.0, 0.0)


def test_a_device_on_a_simulated_clock_reports_only_as_the_clock_moves():
    import usb.core

    clock = SimulatedClock()
    device = EmulatedTrackball(motion=lambda t: (0.0, 0.0, 1.0), clock=clock)
    dev = usb.core.find(backend=device, idVendor=0x1209, idProduct=0x0001)
    dev.set_configuration()
    dev.ctrl_transfer(0x41, 0x03, 100, 0)  # SET_RATE 100 Hz
    dev.ctrl_transfer(0x41, 0x01, 0, 0)    # START
    assert not device.due()
    with pytest.raises(usb.core.USBTimeoutError):
        dev.read(0x81, 32, 5)              # 5 ms of wall time pass, none of the device's
    clock.advance(0.035)                   # three whole periods: one report holds them, as a late host gets
    assert device.due()
    report = bytes(dev.read(0x81, 32, 5))
    assert int.from_bytes(report[8:16], "little") == 30_000 and device.transfers == 1 and not device.due()


@pytest.mark.parametrize("tether", ["free_yaw", "fixed"])
def test_the_frame_loop_moves_as_through_the_ant_source_within_a_count(tether):
    poses = []
    for trackball in (False, True):
        clock = SimulatedClock()
        legs = TrackballLegs(tether, clock=clock) if trackball else AntLocomotion(tether, clock=clock)
        if trackball:
            legs.start()
        loop = FrameLoop(clock=clock, source=getattr(legs, "source", legs), tether=tether,
                         origin=Pose(1.0, 2.0, 0.01, math.radians(30)))
        try:
            for i in range(100):
                legs.walk(0.01, math.radians(9) * math.sin(i / 10))
                loop.step()
            loop.step()
        finally:
            if trackball:
                legs.stop()
        poses.append(loop.pose)
        if trackball:
            status = legs.driver.status()
            assert status["reports"] == 100 and status["gaps"] == 0 and status["quality_avg"] > 0.99
    direct, usb_path = poses
    # 1 m walked: the pose agrees to a fraction of a millimetre (sensor counts of 21 um, remainders carried);
    # in the fixed tether each step's turn is spread over its reports, so it walks a slightly different arc.
    assert math.dist((direct.x, direct.y), (usb_path.x, usb_path.y)) < (5e-5 if tether == "free_yaw" else 5e-4)
    assert abs(math.remainder(direct.heading - usb_path.heading, math.tau)) < 1e-3


@pytest.fixture(scope="module")
def trained():
    """Antcar as the route-following experiments set it up (their eye and oscillation)."""
    model = make_model("antcar", MODEL_EYES["antcar"].n_pn, **MODEL_PARAMS["antcar"])
    with virtual_rig(model, eye_params=MODEL_EYES["antcar"], renderer_kwargs={"face_size": FACE}) as ant:
        learning_walk(ant, ROUTE, 0.01)
    return model


def _release(model, tether, log_path=None, decisions=45):
    with virtual_rig(model, eye_params=MODEL_EYES["antcar"], tether=tether, renderer_kwargs={"face_size": FACE},
                     trackball=True, log_path=log_path) as ant:
        result = follow_route(ant, ROUTE, decisions, arrive_radius=0.05, start_offset=(0.03, math.radians(20)))
        return result, ant.legs.driver.status()


@pytest.mark.parametrize("tether", ["free_yaw", "fixed"])
def test_a_trained_ant_follows_the_route_through_the_emulated_usb_trackball(trained, tether, tmp_path):
    result, status = _release(trained, tether, tmp_path / "ant.h5")
    xy, heading = result.track.arrays()
    _, d, route_heading = ROUTE.project(xy)
    theta = np.degrees(np.remainder(heading - route_heading + math.pi, math.tau) - math.pi)
    assert abs(theta[0]) == pytest.approx(20.0, abs=1.0)
    assert result.summary.arrived and result.summary.errors == 0
    assert np.abs(d).max() < 0.05 and np.all(np.abs(theta[3:]) < 25.0)
    # every step came through the driver (the first decision is taken before any): decoded reports, no gaps,
    # logged as ball samples
    assert status["reports"] >= result.summary.decisions - 1 and status["gaps"] == 0 and status["connected"]
    samples = read_table(tmp_path / "ant.h5", "locomotion")
    assert len(samples["seq"]) == status["reports"]


def test_the_same_path_is_walked_again_on_a_simulated_clock(trained):
    first, _ = _release(trained, "free_yaw", decisions=6)
    second, _ = _release(trained, "free_yaw", decisions=6)
    np.testing.assert_array_equal(first.track.arrays()[0], second.track.arrays()[0])


def test_the_same_code_runs_on_a_real_time_clock(trained):
    clock = MonotonicClock()
    with virtual_rig(trained, eye_params=MODEL_EYES["antcar"], clock=clock, renderer_kwargs={"face_size": FACE},
                     trackball=True, frames_per_decision=2) as ant:
        t0 = clock.now()
        result = follow_route(ant, ROUTE, 8, arrive_radius=0.05)
        frames, elapsed = ant.loop.frame, clock.now() - t0
        status = ant.legs.driver.status()
    assert result.summary.distance > 0.05 and status["reports"] > 0 and status["gaps"] == 0
    assert elapsed >= (frames - 1) / 190.0   # paced by the wall clock: never faster than the frame rate
