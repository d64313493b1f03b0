"""The ant's legs drive the real frame loop through ball rotations, in both tether modes."""

import math

import pytest

from antarium.ant.locomotion import AntLocomotion
from antarium.core.ball import pole_motion
from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.locomotion import BACKENDS, open_source
from antarium.server.frame_loop import FrameLoop


def test_the_ant_is_a_registered_locomotion_backend():
    assert "ant" in BACKENDS
    assert isinstance(open_source("ant", tether="fixed"), AntLocomotion)


def test_free_yaw_ant_rolls_the_ball_along_its_heading():
    ant = AntLocomotion("free_yaw", yaw=0.0, clock=SimulatedClock())
    sample = ant.walk(0.02, math.radians(90))
    dx, dy, dyaw = pole_motion(sample.rotation)
    assert (dx, dy, dyaw) == pytest.approx((0.0, 0.02, 0.0), abs=1e-12)
    assert ant.yaw == pytest.approx(math.pi / 2)
    assert [s.seq for s in ant.read()] == [0] and ant.read() == []


@pytest.mark.parametrize("tether", ["free_yaw", "fixed"])
def test_the_frame_loop_moves_the_pose_as_the_ant_walks(tether):
    clock = SimulatedClock()
    ant = AntLocomotion(tether, clock=clock)
    loop = FrameLoop(clock=clock, source=ant, tether=tether, origin=Pose(1.0, 2.0, 0.01, math.radians(30)))
    for _ in range(10):
        ant.walk(0.01, math.radians(9))
        loop.step()
    # Either way the ant ends at the same place in the world and faces 30 + 90 degrees there.
    world_heading = loop.pose.heading + (ant.yaw if tether == "free_yaw" else 0.0)
    assert math.degrees(world_heading) == pytest.approx(120.0)
    x, y, h = 1.0, 2.0, math.radians(30)
    for _ in range(10):
        h += math.radians(9)
        x, y = x + 0.01 * math.cos(h), y + 0.01 * math.sin(h)
    assert (loop.pose.x, loop.pose.y) == pytest.approx((x, y))
    if tether == "fixed":
        assert math.degrees(loop.pose.heading) == pytest.approx(120.0)   # the scene turned
    else:
        assert math.degrees(loop.pose.heading) == pytest.approx(30.0)    # the ant turned inside the dome


def test_bad_commands_are_refused():
    with pytest.raises(ValueError, match="free_yaw"):
        AntLocomotion("loose")
    ant = AntLocomotion("fixed")
    with pytest.raises(ValueError, match="finite"):
        ant.walk(math.inf, 0.0)
    with pytest.raises(ValueError, match="free_yaw tether"):
        ant.turn_to(1.0)
