"""The servosphere tracker on the simulated camera's frames: calibration, position, body axis, heading, faults."""

import math

import numpy as np
import pytest

from antarium.locomotion.servosphere.rig import SimulatedRig
from antarium.locomotion.servosphere.tracker import Calibration, Tracker, calibrate


@pytest.fixture
def rig():
    return SimulatedRig(apex_px=(300.3, 250.7), mm_per_px=0.05)


def test_calibration_image_gives_the_apex_and_the_scale(rig):
    cal = calibrate(rig.calibration_image(10.0), disc_diameter_mm=10.0)
    assert cal.apex_px == pytest.approx((300.3, 250.7), abs=0.1)  # pixels
    assert cal.mm_per_px == pytest.approx(0.05, rel=0.01)


def test_calibration_refuses_an_image_without_a_disc(rig):
    with pytest.raises(ValueError, match="round disc"):
        calibrate(rig.render())  # an ant is no disc
    with pytest.raises(ValueError, match="uint8"):
        calibrate(np.zeros((4, 4), np.float32))


def test_calibration_maps_both_ways_with_a_rotated_camera():
    cal = Calibration((320.0, 240.0), 0.1, rotation_deg=30.0)
    assert cal.to_mm(*cal.to_px(1.5, -2.0)) == pytest.approx((1.5, -2.0))
    assert cal.to_mm(330.0, 240.0) == pytest.approx((math.cos(math.radians(30)), math.sin(math.radians(30))))


@pytest.mark.parametrize("x_mm, y_mm, heading_deg", [(0.0, 0.0, 0.0), (3.0, -2.0, 35.0), (-5.0, 4.0, 120.0),
                                                     (1.0, 1.0, -80.0)])
def test_position_and_body_axis(rig, x_mm, y_mm, heading_deg):
    rig.ant_xy[:] = (x_mm / 1000, y_mm / 1000)
    rig.ant_heading = math.radians(heading_deg)
    det = Tracker(rig.calibration).update(rig.render())
    assert det.fault is None
    assert (det.x_mm, det.y_mm) == pytest.approx((x_mm, y_mm), abs=0.03)  # mm: half a pixel
    axis_error = math.remainder(det.orientation - math.radians(heading_deg), math.pi)
    assert abs(math.degrees(axis_error)) < 2.0 and -math.pi / 2 <= det.orientation <= math.pi / 2
    assert det.area_mm2 == pytest.approx(math.pi / 4 * 8.0 * 2.5, rel=0.2)


def test_heading_follows_continuity_and_forward_walking(rig):
    tracker = Tracker(rig.calibration)
    rig.ant_heading = math.radians(170.0)
    first = tracker.update(rig.render(), walk_mm_s=(-50.0, 5.0))  # walking toward -x: head at 170 deg
    assert math.degrees(first.heading) == pytest.approx(170.0, abs=2.0)
    for deg in range(170, 240, 10):  # turning through 180 deg: no flip, heading stays continuous
        rig.ant_heading = math.radians(deg)
        det = tracker.update(rig.render())
        assert abs(math.degrees(math.remainder(det.heading - math.radians(deg), math.tau))) < 2.0
    # the same body axis (230 = 50 deg + 180) seen walking toward 50 deg: the head is the end toward 50 deg
    walk = (50 * math.cos(math.radians(50)), 50 * math.sin(math.radians(50)))
    det = tracker.update(rig.render(), walk_mm_s=walk)
    assert abs(math.degrees(math.remainder(det.heading - math.radians(50), math.tau))) < 2.0


def test_no_ant_and_two_blobs_are_faults(rig):
    tracker = Tracker(rig.calibration)
    rig.ant_visible = False
    assert tracker.update(rig.render()).fault == "no_ant"
    rig.ant_visible = True
    rig.distractor_mm = (6.0, 6.0)
    det = tracker.update(rig.render())
    assert det.fault == "two_blobs" and math.isnan(det.heading)
    assert tracker.faults == {"no_ant": 1, "two_blobs": 1}


def test_bad_tracker_settings_are_refused(rig):
    with pytest.raises(ValueError, match="threshold"):
        Tracker(rig.calibration, threshold=0)
    with pytest.raises(ValueError, match="area_mm2"):
        Tracker(rig.calibration, area_mm2=(10.0, 1.0))


@pytest.mark.parametrize("kwargs, message", [({"apex_px": (math.nan, 240.0)}, "apex_px must be 2 finite numbers"),
                                             ({"rotation_deg": math.nan}, "rotation_deg must be a finite number")])
def test_non_finite_calibration_is_refused(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Calibration(**{"apex_px": (320.0, 240.0), "mm_per_px": 0.06, **kwargs})


def test_a_blob_with_a_four_vertex_contour_is_the_ant():
    frame = np.full((480, 640), 200, np.uint8)
    frame[230:250, 253:387] = 40  # an axis-aligned 8.0 x 1.2 mm bar on the apex: its contour is 4 vertices
    det = Tracker(Calibration((320.0, 240.0), 0.06)).update(frame)
    assert det.fault is None
    assert (det.x_mm, det.y_mm) == pytest.approx((-0.03, 0.03), abs=1e-9)  # centre (319.5, 239.5) px
    assert det.orientation == pytest.approx(0.0, abs=1e-9) and det.area_mm2 == pytest.approx(133 * 19 * 0.06 ** 2)


def _ant(rig, x_mm, y_mm, heading=0.0):
    rig.ant_xy[:] = (x_mm / 1000, y_mm / 1000)
    rig.ant_heading = heading
    return rig.render()


def test_a_blob_cut_by_the_frame_border_is_flagged_and_a_dark_rim_ignored(rig):
    cal = rig.calibration
    edge_x = (rig.width - cal.apex_px[0]) * cal.mm_per_px  # mm: the image's right edge
    det = Tracker(cal).update(_ant(rig, edge_x - 1.0, 0.0))  # half the ant out of the frame
    assert det.fault == "ant_at_edge" and math.isnan(det.x_mm)
    frame = _ant(rig, 1.0, 0.5)
    frame[:, :25] = 30  # a dark rim at the frame's left edge, of an ant's area
    det = Tracker(cal).update(frame)
    assert det.fault is None and (det.x_mm, det.y_mm) == pytest.approx((1.0, 0.5), abs=0.05)


def test_a_one_pixel_crack_does_not_split_the_ant(rig):
    cal = rig.calibration
    frame = _ant(rig, 0.0, 0.0)
    px, py = (int(round(v)) for v in cal.to_px(0.0, 0.0))
    frame[py - 40:py + 40, px] = 250  # a 1 px bright line across its waist (a glint, a scratch on the lens)
    det = Tracker(cal).update(frame)
    assert det.fault is None and (det.x_mm, det.y_mm) == pytest.approx((0.0, 0.0), abs=0.05)
