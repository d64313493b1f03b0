"""The polarised UV pixels end to end: sky e-vector -> renderer angle -> POLARISER codes -> emulated aircore
actuators -> the e-vector the compass reads back; wrap-around at 0/180 deg; updates deferred by the link budget in
the fixed tether; and the encoder's refusals (one ValueError line naming what was wrong)."""

import math

import numpy as np
import pytest

from antarium.ant.compass import e_vectors_from_polarisers
from antarium.core.clock import SimulatedClock
from antarium.core.pose import Pose
from antarium.firmware_proto import polariser
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import open_link
from antarium.geometry import load_dome
from antarium.renderers import Renderer
from antarium.renderers.output import polariser_angles
from antarium.renderers.sky import e_vector, sun_direction
from antarium.server.frame_loop import FrameLoop


def axis_error_deg(a, b) -> float:
    """Largest difference between e-vector axes given as angles (rad, modulo pi), in degrees."""
    return math.degrees(float(np.abs((np.asarray(a) - np.asarray(b) + np.pi / 2) % np.pi - np.pi / 2).max()))


def test_a_one_panel_update_to_the_all_address_is_refused():
    """9 angles addressed to 63 (all panels) made a 22-byte datagram that every distributor rejects (63 takes
    55 x 9 angles, 994 bytes): the update was silently lost (until 2026-11-28)."""
    with pytest.raises(ValueError, match=r"address 63 out of range: allowed 0\.\.54$"):
        polariser.encode_polarisers(np.full(9, 1.0), panel=63)
    emu = Emulator(clock=SimulatedClock())
    emu.handle_datagram(polariser.encode_polarisers(np.full(9, 1.0), panel=54))  # a panel still takes 9
    assert emu.counters["polariser_updates"] == 1
    assert axis_error_deg(emu.actuators.target[54], np.full(9, 1.0)) < 0.01


def test_an_out_of_range_angle_is_named_as_a_plain_number():
    """The message showed numpy's repr, "is np.float64(3.141592653589793) rad" (until 2026-11-28)."""
    angles = np.zeros((55, 9))
    angles[5, 1] = math.pi
    with pytest.raises(ValueError) as err:
        polariser.encode_polarisers(angles)
    assert str(err.value) == "polariser angle at (5, 1) is 3.141592653589793 rad: allowed [0, pi)"


@pytest.mark.parametrize("angles", [["north"] * 9, [1j] * 9, np.full(9, 0.5 + 0.5j)])
def test_angles_that_are_not_real_numbers_are_one_value_error(angles):
    """A string gave "could not convert string to float" (no word of polarisers), a complex number a TypeError
    (which the frame loop does not catch), a complex array its real part with a warning (until 2026-11-28)."""
    with pytest.raises(ValueError, match=r"^polariser angles must be real numbers \(radians\), got "):
        polariser.encode_polarisers(angles, panel=3)
    with pytest.raises(ValueError, match=r"^polariser angles must be real numbers"):
        polariser.wrap_angles(angles)


def test_sky_e_vectors_survive_the_wire_and_the_actuators():
    """The angle sense and reference of renderer, wire and emulated actuators agree: the compass reads back the
    sky's e-vector at every UV pixel (to the 16-bit code's resolution), for suns all round."""
    dome = load_dome()
    uv = np.asarray(dome.uv_index)
    dirs = np.asarray(dome.directions, np.float64)[uv]
    axes = np.asarray(dome.panel_axes)[np.asarray(dome.panel)[uv]]
    clock = SimulatedClock()
    emu = Emulator(clock=clock)
    for az, el in [(0, 30), (135, 40), (270, 10), (45, 80)]:
        e = e_vector(dirs, sun_direction(math.radians(az), math.radians(el)))
        emu.handle_datagram(polariser.encode_polarisers(polariser_angles(dirs, e, axes).reshape(55, 9)))
        clock.advance(1.0)
        back = e_vectors_from_polarisers(dirs, emu.polariser_angles().reshape(-1), axes)
        seen = np.linalg.norm(e, axis=1) > 0.5  # not towards or away from the sun
        cos = np.abs(np.einsum("ij,ij->i", back, e))[seen] / np.linalg.norm(back[seen], axis=1)
        assert math.degrees(np.arccos(min(1.0, cos.min()))) < 0.005
    assert emu.actuators.holding(clock.now()).all()


def test_an_e_vector_across_0_and_180_deg_turns_the_short_way():
    clock = SimulatedClock()
    link = open_link("virtual", clock=clock)
    link.send_polarisers(np.full((55, 9), math.radians(0.5)))
    clock.advance(1.0)
    rotor = link.emulator.actuators.rotor_angle(clock.now()).copy()
    link.send_polarisers(np.full((55, 9), math.radians(179.5)))
    assert np.allclose(np.degrees(link.emulator.actuators.target - rotor), -1.0, atol=0.01)
    clock.advance(1.0)
    t = link.telemetry(wait_s=0.1)
    assert axis_error_deg(np.radians(t["polariser_angles_deg"]), np.full((55, 9), math.radians(179.5))) < 0.01
    assert np.asarray(t["holding"]).all()


def test_fixed_tether_the_polarisers_end_on_the_latest_heading_despite_deferred_updates():
    """At 190 frames/s an update does not fit every period; with the ant turning every frame some are deferred,
    and the dome must still end on the sky of the last heading."""
    clock = SimulatedClock()
    renderer = Renderer(load_dome(), face_size=64, path="cpu", clock=clock)
    renderer.set_scene({"scene": "sky", "sun_azimuth_deg": 135, "sun_elevation_deg": 40})
    link = open_link("virtual", clock=clock)
    loop = FrameLoop(clock=clock, source=None, renderer=renderer, link=link, rate_hz=190, tether="fixed",
                     origin=Pose(0, 0, 0.01, 0.0))
    for k in range(30):
        loop.pose = Pose(0, 0, 0.01, math.radians(3.0 * k))
        loop.step()
    loop.step()
    assert loop.link_budget.deferred > 0
    clock.advance(0.5)
    assert axis_error_deg(link.emulator.polariser_angles(), renderer.polariser_angles()) < 0.01
