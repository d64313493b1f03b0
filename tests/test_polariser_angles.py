"""Polariser angles from the sky to the dome: always in [0, pi), and an update the link refused is tried again."""

import math

import numpy as np

from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.polariser import angles_to_codes, wrap_angles
from antarium.geometry import load_dome
from antarium.renderers import Renderer
from antarium.renderers.output import polariser_angles
from antarium.renderers.sky import e_vector
from antarium.server.frame_loop import FrameLoop


def axis_error(a, b) -> float:
    """Largest difference between e-vector axes (rad, modulo pi)."""
    return float(np.abs((np.asarray(a) - np.asarray(b) + np.pi / 2) % np.pi - np.pi / 2).max())


def test_wrap_angles_keeps_every_axis_in_zero_to_pi():
    a = wrap_angles([-1e-20, -1e-17, 0.0, math.pi, 4.0, -1.0, 7 * math.pi / 4])
    assert a.tolist()[:4] == [0.0, 0.0, 0.0, 0.0]  # np.mod(-1e-20, pi) is pi itself: the same axis as 0
    assert (a >= 0).all() and (a < math.pi).all()
    assert axis_error(a, [0, 0, 0, 0, 4.0, -1.0, 7 * math.pi / 4]) < 1e-12
    angles_to_codes(a)  # every one encodes


def test_an_angle_a_hair_below_zero_is_zero_not_pi():
    """Panel axes x, y, n = the dome's; a UV pixel looking along n with the wanted e-vector a hair clockwise of +x."""
    axes = np.eye(3)[None]
    angle = polariser_angles(np.array([[0.0, 0.0, 1.0]]), np.array([[1.0, -1e-20, 0.0]]), axes)
    assert angle.tolist() == [0.0]


def test_sky_angles_at_the_default_start_are_all_encodable():
    """Sun at azimuth 0, elevation 30 deg, heading 0 (the default start): three UV pixels' angles were pi itself,
    and the link refused the whole update (until 2026-11-27)."""
    dome = load_dome()
    uv = np.asarray(dome.uv_index)
    dirs = np.asarray(dome.directions, np.float64)[uv]
    axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
    e = math.radians(30)
    angles = polariser_angles(dirs, e_vector(dirs, np.array([math.cos(e), 0.0, math.sin(e)])), axes)
    assert (angles >= 0).all() and (angles < math.pi).all()
    assert angles_to_codes(angles.reshape(55, 9)).shape == (55, 9)


def test_the_dome_follows_the_sky_at_the_default_start():
    clock = SimulatedClock()
    renderer = Renderer(load_dome(), face_size=64, path="cpu", clock=clock)
    renderer.set_scene({"scene": "sky", "sun_azimuth_deg": 0, "sun_elevation_deg": 30})
    link = open_link("virtual", clock=clock)
    loop = FrameLoop(clock=clock, source=None, renderer=renderer, link=link, rate_hz=190,
                     origin=Pose(0, 0, 0.01, 0.0))
    loop.run(frames=5)
    assert "link" not in loop.faults
    assert link.emulator.counters["polariser_updates"] == 1
    assert axis_error(link.emulator.actuators.target, renderer.polariser_angles()) < 1e-4


class OnceRefusedRenderer:
    """A still renderer whose first polariser angles hold pi itself (what renderers/output.py returned for some
    skies until 2026-11-27), then pi/4 everywhere; the pose never changes."""

    scene = None

    def __init__(self):
        self.calls = 0

    def render(self, pose, out=None):
        return np.zeros((20350, 2), np.uint16) if out is None else out

    def polariser_angles(self):
        self.calls += 1
        angles = np.full((55, 9), math.pi / 4)
        if self.calls == 1:
            angles[5, 1] = math.pi
        return angles


def test_a_refused_polariser_update_is_tried_again_with_the_next_frame():
    """The loop recorded the heading of a refused update as sent, so at an unchanged heading it never tried
    again and the dome kept its old polarisers."""
    clock = SimulatedClock()
    link = open_link("virtual", clock=clock)
    loop = FrameLoop(clock=clock, source=None, renderer=OnceRefusedRenderer(), link=link, rate_hz=190)
    loop.run(frames=3)
    assert loop.faults.get("link") == 1  # the first update refused, and counted
    assert link.emulator.counters["polariser_updates"] == 1
    assert axis_error(link.emulator.actuators.target, np.full((55, 9), math.pi / 4)) < 1e-4
