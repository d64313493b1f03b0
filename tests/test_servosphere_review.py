"""The servosphere's camera: one test class run against every camera back-end (`simulated`: the rig's rendered
frames; `opencv`: OpenCV's VideoCapture reading a video file of those frames, the lowest seam short of a camera),
what the loop does with frames it cannot use (none, or not a uint8 (H, W) image), and unknown keys in the
[locomotion] tables."""

import math

import cv2
import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.locomotion.servosphere import CAMERAS, open_camera, source
from antarium.locomotion.servosphere.source import FAULTS, ServosphereSource
from antarium.locomotion.servosphere.tracker import Tracker

ANT_MM = (1.5, -2.0)  # where the ant stands in every frame (mm from the apex)


def _rig_at(clock, x_mm, y_mm):
    from antarium.locomotion.servosphere.rig import SimulatedRig

    rig = SimulatedRig(clock, speed=0.0, meander=0.0, noise_sd=1.0)
    rig.ant_xy[:] = (x_mm / 1000, y_mm / 1000)
    rig.ant_heading = math.radians(30.0)
    return rig


def _video(path, rig, n):
    """An MJPG video file of `n` frames of `rig`'s camera: what OpenCV's VideoCapture reads like a camera."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 700, (rig.width, rig.height), isColor=False)
    for _ in range(n):
        writer.write(rig.render())
    writer.release()
    return str(path)


@pytest.fixture(params=sorted(CAMERAS))
def camera(request, tmp_path):
    """(camera, calibration of its frames)"""
    clock = SimulatedClock()
    rig = _rig_at(clock, *ANT_MM)
    if request.param == "simulated":
        cam = open_camera("simulated", rig=rig)
        yield cam, rig.calibration
    else:
        cam = open_camera("opencv", index=_video(tmp_path / "ant.avi", rig, 6), clock=clock)
        yield cam, rig.calibration
    cam.close()


class TestEveryCamera:
    def test_frames_are_uint8_monochrome_in_time_order(self, camera):
        cam, _ = camera
        assert cam.frame_rate > 0
        times = []
        for _ in range(3):
            t, frame = cam.grab()
            times.append(t)
            assert frame.dtype == np.uint8 and frame.ndim == 2 and frame.size > 0
        assert times == sorted(times)

    def test_the_tracker_finds_the_ant_where_it_stands(self, camera):
        cam, calibration = camera
        det = Tracker(calibration).update(cam.grab()[1])
        assert det.fault is None
        assert (det.x_mm, det.y_mm) == pytest.approx(ANT_MM, abs=0.06)  # mm: one pixel (MJPEG's losses)


def test_an_opencv_camera_out_of_frames_gives_none_without_raising(tmp_path):
    clock = SimulatedClock()
    rig = _rig_at(clock, *ANT_MM)
    cam = open_camera("opencv", index=_video(tmp_path / "short.avi", rig, 2), clock=clock)
    assert cam.grab()[1] is not None and cam.grab()[1] is not None
    t, frame = cam.grab()  # a dropped frame, the end of a video: no frame, for the loop to count
    assert frame is None and t == clock.now()
    cam.close()


def test_opencv_camera_that_cannot_open_is_one_line(tmp_path):
    with pytest.raises(RuntimeError, match="cannot open camera .*allowed: a device index or a video URL"):
        open_camera("opencv", index=str(tmp_path / "missing.avi"))


def test_unknown_or_unhashable_camera_names_what_is_allowed():
    for name in ("basler", ["opencv"]):
        with pytest.raises(ValueError, match=r"unknown servosphere camera .*; allowed: opencv, simulated"):
            open_camera(name)


@pytest.mark.parametrize("bad", [lambda f: None, lambda f: f.astype(np.float64), lambda f: np.dstack([f] * 3),
                                 lambda f: f[:0]], ids=["no frame", "float64", "colour", "empty"])
def test_a_bad_frame_is_a_fault_the_ball_stops_and_the_loop_goes_on(bad):
    clock = SimulatedClock()
    src = ServosphereSource(clock=clock, simulation={"seed": 2})
    rows = []
    src.use_log(type("Rows", (), {"add_servosphere": staticmethod(rows.append)})())
    render, k = src.rig.render, [0]

    def camera_image():
        k[0] += 1
        return bad(render()) if 300 <= k[0] < 310 else render()

    src.rig.render = camera_image
    for _ in range(100):
        clock.advance(1 / 190)
        src.read()
    bit = 1 << FAULTS.index("bad_frame")
    bad_rows = [r for r in rows if r[-1] & bit]
    assert [r[1] for r in bad_rows] == list(range(300, 310))
    assert all(math.isnan(r[2]) for r in bad_rows)  # no position from a frame without one
    assert src.status()["connected"] and src.status()["faults"]["bad_frame"] == 10
    assert not any(r[-1] for r in rows[330:])  # tracked again after the gap
    assert math.hypot(*rows[-1][2:4]) < 2.0  # the ant still on the apex (mm)
    src.stop()


def test_a_camera_that_keeps_giving_nothing_ends_the_loop_with_one_line():
    clock = SimulatedClock()
    src = ServosphereSource(clock=clock, simulation={"seed": 2})
    src.rig.render = lambda: None
    n = source.MAX_BAD_FRAMES
    with pytest.raises(RuntimeError) as info:
        for _ in range(n):
            clock.advance(1 / 190)
            src.read()
    assert str(info.value) == (f"the camera gave no usable frame in the last {n} (no frame); "
                               "allowed: uint8 (H, W) monochrome frames")
    assert src.loop.frame == n - 1
    src.stop()


@pytest.mark.parametrize("table, cfg, allowed", [
    ("simulation", {"speed": 0.05, "bogus": 1}, "meander"),
    ("simulation", {"geometry": None}, "speed"),  # the source sets it: not the user's
    ("rotors", {"azimuth": [0, 120, 240]}, "azimuth_deg, elevation_deg, sphere_radius, wheel_radius"),
    ("steppers", {"microsteps": 16}, "max_accel, max_rate, steps_per_rev"),
])
def test_an_unknown_key_in_a_table_is_one_line_naming_the_allowed(table, cfg, allowed):
    with pytest.raises(ValueError, match=rf"servosphere {table} has no option '\w+'; allowed: .*{allowed}") as info:
        ServosphereSource(clock=SimulatedClock(), **{table: cfg})
    assert "\n" not in str(info.value) and "clock" not in str(info.value)
