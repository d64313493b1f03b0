"""The frame loop's semantics on a simulated clock: a command between frames applies at the time it runs (the motion
measured before it moves the pose under the old state), late frames are all told, bad tethers and clock steps are
refused in one line."""

import math

import pytest

from antarium.core.ball import check_tether
from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.locomotion import BallSample, LocomotionSource
from antarium.server.frame_loop import FrameLoop

FORWARD_1MM = (0.0, -0.02, 0.0)  # rad about the dome axes: 1 mm along the dome's +x on the 5 cm ball


class QueuedSource(LocomotionSource):
    """A driver's queue: samples put in are stamped with the clock at their arrival and read once."""

    def __init__(self, clock):
        self.clock, self.queue, self.seq = clock, [], 0

    def put(self, rotation):
        self.seq += 1
        self.queue.append(BallSample(self.clock.now(), self.seq, rotation))

    def read(self):
        out, self.queue = self.queue, []
        return out

    def status(self):
        return {"connected": True}


def walked_then_command(**kwargs):
    """A loop after one frame, with 1 mm walked forward since (arrived before the command the test gives next)."""
    clock = SimulatedClock()
    source = QueuedSource(clock)
    records, events = [], []
    loop = FrameLoop(clock=clock, source=source, on_frame=records.append,
                     on_event=lambda t, kind, data: events.append((kind, data)), **kwargs)
    loop.step()
    clock.advance(0.002)
    source.put(FORWARD_1MM)
    clock.advance(0.001)
    return loop, records, events


@pytest.mark.parametrize("call_soon", [False, True])
def test_set_pose_shows_the_pose_set_not_moved_by_earlier_motion(call_soon):
    loop, records, events = walked_then_command()
    target = Pose(1.0, 2.0, 0.01, 0.3)
    if call_soon:  # as the server's command handlers run it
        loop.call_soon(loop.set_pose, target)
    else:
        loop.set_pose(target)
    loop.step()
    assert records[-1].pose == target
    assert events[-1] == ("pose_set", {"x": 1.0, "y": 2.0, "z": 0.01, "heading": 0.3})
    assert records[-1].sample_seq == 1 and loop.samples_used == 1  # the sample is still the frame's, and logged


def test_reset_origin_shows_the_origin():
    loop, records, _ = walked_then_command(origin=Pose(0.5, -0.25, 0.01, 1.0))
    loop.reset_origin()
    loop.step()
    assert records[-1].pose == Pose(0.5, -0.25, 0.01, 1.0) and records[-1].scene_rotation == 0.0


def test_motion_before_a_scene_rotation_goes_where_the_ant_faced_then():
    loop, records, _ = walked_then_command()
    loop.rotate_scene(math.pi / 2)
    loop.step()
    pose = records[-1].pose
    assert (pose.x, pose.y) == pytest.approx((0.001, 0.0), abs=1e-12)
    assert pose.heading == pytest.approx(-math.pi / 2)


@pytest.mark.parametrize("closed_before, expected_x", [(True, 0.001), (False, 0.0)])
def test_loop_switch_applies_to_motion_after_it(closed_before, expected_x):
    loop, records, _ = walked_then_command(closed_loop=closed_before)
    loop.set_closed_loop(not closed_before)
    loop.step()
    assert records[-1].pose.x == pytest.approx(expected_x, abs=1e-12)


def test_gain_change_applies_to_motion_after_it():
    loop, records, _ = walked_then_command()
    loop.set_gains(translation=-2.0)
    loop.step()
    assert records[-1].pose.x == pytest.approx(0.001, abs=1e-12)  # walked at gain 1 before the change


def test_tether_change_applies_to_motion_after_it():
    clock = SimulatedClock()
    source = QueuedSource(clock)
    loop = FrameLoop(clock=clock, source=source, tether="fixed")
    loop.step()
    source.put((0.0, 0.0, -0.1))  # the fixed ant turned 0.1 rad counter-clockwise
    loop.set_tether("free_yaw")
    rec = loop.step()
    assert rec.pose.heading == pytest.approx(0.1) and not rec.fixed_tether


def test_every_late_frame_is_told_in_the_late_frames_events():
    clock = SimulatedClock()

    class SlowRenderer:
        cost = 0.0

        def render(self, pose, out=None):
            clock.advance(self.cost)
            return out

    renderer, events = SlowRenderer(), []
    loop = FrameLoop(clock=clock, source=None, renderer=renderer,
                     on_event=lambda t, kind, data: events.append(data) if kind == "late_frames" else None)
    loop.run(frames=5)
    renderer.cost = 0.008  # 1.5 periods at 190 Hz: 20 late frames in a row, within 0.3 s
    loop.run(frames=20)
    renderer.cost = 0.0
    loop.run(frames=10)  # the run ends before a second has passed: the held-back ones are told at its end
    assert loop.late_frames == 20
    assert sum(e["count"] for e in events) == 20 and events[-1]["total"] == 20


@pytest.mark.parametrize("bad", [["fixed"], {"fixed": 1}, None, 3])
def test_a_tether_of_the_wrong_type_is_refused_in_one_line(bad):
    with pytest.raises(ValueError, match="tether must be one of 'free_yaw', 'fixed'"):
        check_tether(bad)
    loop = FrameLoop(clock=SimulatedClock(), source=None)
    with pytest.raises(ValueError, match="tether must be one of"):
        loop.set_tether(bad)
    assert loop.tether == "free_yaw"


@pytest.mark.parametrize("dt", [math.nan, math.inf, -1.0, "1"])
def test_simulated_clock_refuses_a_step_that_is_not_a_finite_time(dt):
    clock = SimulatedClock(2.0)
    with pytest.raises(ValueError, match="dt must be a finite number of seconds >= 0"):
        clock.advance(dt)
    assert clock.now() == 2.0


@pytest.mark.parametrize("start", [math.nan, -math.inf])
def test_simulated_clock_refuses_a_start_that_is_not_a_finite_time(start):
    with pytest.raises(ValueError, match="start must be a finite number of seconds"):
        SimulatedClock(start)
