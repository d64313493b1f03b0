"""Review of the locomotion sources: calibration that lost motion, replay files that loop in no time or are cut
short, a scripted path with points that are not finite."""

import math

import numpy as np
import pytest

from antarium.cli import main
from antarium.core.clock import SimulatedClock
from antarium.locomotion.replay import ReplaySource
from antarium.locomotion.scripted import ScriptedSource
from antarium.locomotion.trackball import calibration
from antarium.locomotion.trackball import config as tbconfig
from antarium.locomotion.trackball.driver import UsbTrackball

RIG = """# the lab's rig
[trackball]
resolution_cpi = 1200
"""


def test_cli_calibrate_refuses_a_turn_whose_reports_were_lost_and_writes_nothing(tmp_path, capsys, emulated_hands,
                                                                                 monkeypatch):
    """Reports lost during a turn take their counts with them: the counts per mm would come out too low. The
    command names the loss, returns 2 and leaves the rig file as it was."""
    rig = tmp_path / "rig.toml"
    rig.write_text(RIG)
    real_turn, lost = calibration.turn_emulated, []

    def first_turn_loses_reports(driver, backend, axis, turns, **kwargs):
        """40 reports of the first turn lost, counted from the turn's start: the emulator sends as fast as it is
        read, so a fixed report number fell before the turn when the machine was busy (a fresh-clone CI)."""
        if not lost:
            schedule = backend.motion.schedule

            def schedule_and_lose(start, *args):
                first = round(start * backend.rate_hz) + 100  # the report number 100 periods into the turn
                backend.faults.update({n: "drop" for n in range(first, first + 40)})
                lost.append(axis)
                return schedule(start, *args)

            monkeypatch.setattr(backend.motion, "schedule", schedule_and_lose)
        return real_turn(driver, backend, axis, turns, **kwargs)

    monkeypatch.setattr(calibration, "turn_emulated", first_turn_loses_reports)
    assert main(["trackball", "calibrate", "--config", str(rig), "--turns", "0.25"]) == 2
    assert lost == ["z"]
    err = capsys.readouterr().err
    assert "turn about z" in err and "lost_reports +40" in err, err
    assert rig.read_text() == RIG


def test_measure_refuses_a_turn_during_which_the_device_was_unplugged():
    config = tbconfig.TrackballConfig()
    backend = calibration.miscalibrated_emulator(config, realtime=False)

    def turn_with_unplug(driver, axis, turns):
        counts = calibration.turn_emulated(driver, backend, axis, turns)
        backend.unplug()  # the cable pulled before Enter: the device comes back, its counts meanwhile do not
        while driver.counters["unplugs"] == 0:
            driver._stop.wait(0.001)
        backend.replug()
        return counts

    with UsbTrackball(trackball=config, backend=backend) as driver:
        driver.wait_connected(5.0)
        good = calibration.measure(driver, "z", 0.25, lambda d, a, t: calibration.turn_emulated(d, backend, a, t))
        assert good.axis == "z" and good.turns == 0.25 and abs(good.counts[0]) > 1000
        with pytest.raises(calibration.CalibrationError, match=r"turn about x lost motion: unplugs \+1"):
            calibration.measure(driver, "x", 0.25, turn_with_unplug)


def test_looped_replay_of_samples_at_one_time_is_refused_not_a_hang(tmp_path):
    path = tmp_path / "same_t.csv"
    path.write_text("t,rx,ry,rz\n0.5,0.01,0,0\n0.5,0.02,0,0\n")
    with pytest.raises(ValueError, match=r"all 2 samples are due at one time \(t = 0.5 s\), so it cannot be looped"):
        ReplaySource(str(path), loop=True, clock=SimulatedClock())
    once = ReplaySource(str(path), clock=SimulatedClock())  # played once, they are fine
    assert [s.rotation[0] for s in once.read()] == [0.01, 0.02]


def test_looped_replay_of_a_recording_with_repeated_times_still_loops(tmp_path):
    """Most samples share their time with the previous one (read in batches; the median step is 0): a lap lasts
    the recording's span, each next lap's first batch coming with the previous lap's last one."""
    path = tmp_path / "batches.csv"
    path.write_text("t,seq,rx,ry,rz\n0,0,1,0,0\n0,1,1,0,0\n0,2,1,0,0\n0.01,3,1,0,0\n")
    clock = SimulatedClock()
    src = ReplaySource(str(path), loop=True, clock=clock)
    src.start()
    clock.advance(0.025)
    seqs = [s.seq for s in src.read()]
    assert seqs == list(range(11))  # laps at 0, 0.01 and 0.02 s; the third lap's last sample is due at 0.03 s


@pytest.mark.parametrize(("text", "match"), [
    ("t,rx,ry,rz\n0.0,0.01,0,0\n0.001,0.01\n", r"line 3: .*rz.*(missing|cut short)"),
    ("t,rx,ry,rz\n0,0,0,0\n\n\n0.001,x,0,0\n", r"line 5: could not convert string to float: 'x'"),
    ("t,rx,ry,rz\n0,0,0,0\n\n0.001,nan,0,0\n", r"line 4: rx must be a finite number, got nan"),
])
def test_replay_csv_cut_short_or_bad_names_its_line(tmp_path, text, match):
    path = tmp_path / "rec.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=match):
        ReplaySource(str(path))


def test_replay_csv_that_is_not_text_names_the_file(tmp_path):
    path = tmp_path / "log.csv"
    path.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(range(256)))
    with pytest.raises(ValueError, match=r"replay CSV .*log\.csv.* is not UTF-8 text"):
        ReplaySource(str(path))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_scripted_path_with_a_point_that_is_not_finite_is_refused(bad):
    with pytest.raises(ValueError, match=r"path point #1 must be finite"):
        ScriptedSource(path=[(0.0, 0.0), (bad, 1.0)], clock=SimulatedClock())


def test_scripted_path_is_followed_to_its_end():
    clock = SimulatedClock()
    src = ScriptedSource(path=[(0.0, 0.0), (0.01, 0.0), (0.01, 0.01)], speed=0.02, rate_hz=100.0, clock=clock)
    src.start()
    clock.advance(2.0)
    rot = np.array([s.rotation for s in src.read()])
    walked = np.array([-rot[:, 1].sum(), rot[:, 0].sum()]) * src.radius  # free_yaw: (ry, rx) = (-dx, dy) / R
    np.testing.assert_allclose(walked, [0.01, 0.01], atol=1e-12)


STALE = """# calibrated at 1200 cpi; the lab has since asked the sensors for 2400
[trackball]
resolution_cpi = 2400

[[trackball.sensors]]
azimuth_deg = 0.0
counts_per_mm = [50.0, 48.0]  # lens A
calibration_cpi = 1200

[[trackball.sensors]]
azimuth_deg = 90.0
counts_per_mm = [47.0, 46.0]
signs = [1, -1]
calibration_cpi = 1200
"""


def test_cli_calibrate_measures_a_rig_calibrated_at_another_resolution_anew(tmp_path, capsys, emulated_hands):
    """Loading such a rig is refused with 'calibrate again'; calibrate itself must then work, not refuse it too."""
    rig = tmp_path / "rig.toml"
    rig.write_text(STALE)
    with pytest.raises(tbconfig.TrackballConfigError, match="calibrate again"):
        tbconfig.load(rig)
    assert main(["trackball", "calibrate", "--config", str(rig), "--turns", "0.25"]) == 0, capsys.readouterr().err
    assert "every other line is unchanged" in capsys.readouterr().out
    text = rig.read_text()
    assert "# calibrated at 1200 cpi" in text and "# lens A" in text
    config = tbconfig.load(rig)
    assert [s.calibration_cpi for s in config.sensors] == [2400, 2400]
    nominal = 2400 / 25.4  # the emulated lens differs from the nominal counts per mm of 2400 cpi by known factors
    np.testing.assert_allclose([v for s in config.sensors for v in s.counts_per_mm],
                               [nominal * f for f in calibration.EMULATED_CPMM_FACTORS], rtol=5e-3)
    assert [g for s in config.sensors for g in s.signs] == [1, 1, 1, 1]  # the file's [1, 1, 1, -1], y1 flipped
