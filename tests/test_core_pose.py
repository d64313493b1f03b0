"""The eye pose: SI units, headings kept in [-pi, pi]."""

import math

import pytest

from antarium.config import resolve
from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.server.frame_loop import FrameLoop


@pytest.mark.parametrize("heading_deg, expected_deg", [(450.0, 90.0), (-270.0, 90.0), (3600.0, 0.0), (180.0, 180.0),
                                                      (-180.0, -180.0), (30.0, 30.0)])
def test_a_heading_outside_a_turn_is_wrapped(heading_deg, expected_deg):
    assert Pose.from_deg(0.0, 0.0, heading_deg=heading_deg).heading_deg == pytest.approx(expected_deg, abs=1e-9)


def test_a_start_heading_beyond_180_deg_gives_no_jump_in_the_logged_heading():
    """[loop] start_heading_deg = 450 (the config takes -3600..3600) was kept as 7.85 rad until the first walked
    frame wrapped it: a 2 pi step in the frames table and the pose stream with no turn."""
    loop = FrameLoop.from_config(resolve({"loop": {"start_heading_deg": 450.0}}).loop, clock=SimulatedClock(),
                                 source=None)
    assert loop.pose.heading == pytest.approx(math.pi / 2)
    loop.reset_origin()
    assert loop.pose.heading == pytest.approx(math.pi / 2)
    loop.set_pose(Pose(1.0, 2.0, 0.01, math.radians(-540.0)))
    assert abs(loop.pose.heading) == pytest.approx(math.pi)
