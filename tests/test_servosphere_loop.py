"""The servosphere in closed loop on the simulated rig (SimulatedClock: faster than real time): the ant is kept
on the apex, the ball's rotation reconstructs its walk, and every fault stops the ball while the loop goes on."""

import math

import numpy as np
import pytest

from antarium.core.ball import pole_motion
from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.locomotion.servosphere.source import FAULTS, _calibration


class Rows:
    def __init__(self):
        self.rows = []

    def add_servosphere(self, row):
        self.rows.append(row)


def _run(src, clock, seconds, path=None):
    for _ in range(int(round(seconds * 190))):
        clock.advance(1 / 190)
        for s in src.read():
            if path is not None:
                path += pole_motion(s.rotation, src.loop.geometry.sphere_radius)[:2]


@pytest.fixture
def sim():
    clock = SimulatedClock()
    src = open_source("servosphere", clock=clock, simulation={"seed": 4, "speed": 0.05, "meander": 2.0,
                                                              "slip": 0.005})
    log = Rows()
    src.use_log(log)
    src.start()
    yield src, clock, log.rows
    src.stop()


def test_the_ant_stays_on_the_apex_and_the_ball_reconstructs_its_path(sim):
    src, clock, rows = sim
    path = np.zeros(2)
    _run(src, clock, 3.0, path)
    rig = src.rig
    err = np.array([math.hypot(r[2], r[3]) for r in rows[70:]])  # mm, after the first 0.1 s
    assert np.all(np.isfinite(err))
    assert np.median(err) <= 2.0 and np.percentile(err, 99) <= 5.0
    assert rig.walked == pytest.approx(0.15, rel=0.01)  # 3 s at 5 cm/s
    assert np.hypot(*(path - rig.true_path)) <= 0.02 * rig.walked
    headings = np.array([r[5] for r in rows[70:]])
    assert abs(math.remainder(headings[-1] - rig.ant_heading, math.tau)) < math.radians(5)
    assert not any(r[-1] for r in rows)  # no fault
    assert rows[-1][1] == len(rows) and len(rows) == pytest.approx(3.0 * 700, abs=2)  # 700 frames/s


def _run_reporting(src, clock, rows, fault, seconds=0.1):
    n = len(rows)
    _run(src, clock, seconds)
    assert src.status()["faults"][fault] > 0 and any(r[-1] & (1 << FAULTS.index(fault)) for r in rows[n:])


def test_faults_stop_the_ball_and_the_loop_goes_on(sim):
    src, clock, rows = sim
    _run(src, clock, 0.5)
    rig = src.rig
    for fault, start, end in [
        ("no_ant", lambda: setattr(rig, "ant_visible", False), lambda: setattr(rig, "ant_visible", True)),
        ("two_blobs", lambda: setattr(rig, "distractor_mm", (8.0, 8.0)), lambda: setattr(rig, "distractor_mm", None)),
        ("stall", lambda: rig.firmware.stalled.__setitem__(0, True),
         lambda: rig.firmware.stalled.__setitem__(0, False)),
        ("link_timeout", lambda: setattr(rig.port, "drop_prob", 1.0), lambda: setattr(rig.port, "drop_prob", 0.0)),
    ]:
        start()
        _run_reporting(src, clock, rows, fault)
        assert np.all(rig.firmware.rate == 0) and np.linalg.norm(rig.omega) < 1e-3, fault  # the ball stopped
        end()
        _run(src, clock, 0.5)
        assert math.hypot(*rows[-1][2:4]) < 2.0 and rows[-1][-1] == 0, fault  # tracking again, no fault
        assert np.any(rig.firmware.rate != 0), fault


def test_a_garbling_line_is_reported_and_the_ant_kept(sim):
    src, clock, rows = sim
    src.rig.port.garble_prob = 0.05
    _run(src, clock, 1.0)
    faults = src.status()["faults"]
    assert faults["link_garbled"] > 0
    err = np.array([math.hypot(r[2], r[3]) for r in rows[70:]])
    assert np.percentile(err, 99) <= 5.0


def test_bad_source_options_name_what_is_allowed():
    with pytest.raises(ValueError, match="both 'simulated'"):
        open_source("servosphere", camera="simulated", link="serial", clock=SimulatedClock())
    with pytest.raises(ValueError, match="slip"):
        open_source("servosphere", simulation={"slip": 0.9}, clock=SimulatedClock())
    with pytest.raises(ValueError, match="calibration"):
        _calibration(None)


def test_counter_rotation_holds_the_ants_heading():
    def heading_spread(counter_rotate):
        clock = SimulatedClock()
        src = open_source("servosphere", clock=clock, counter_rotate=counter_rotate,
                          tether="fixed" if counter_rotate else "free_yaw",
                          simulation={"seed": 6, "speed": 0.05, "meander": 2.0})
        log = Rows()
        src.use_log(log)
        _run(src, clock, 1.0)
        headings = np.array([r[5] for r in log.rows[300:]])
        spread = np.abs(np.remainder(headings + math.pi, math.tau) - math.pi)  # rad from yaw_ref 0
        yaw = sum(s.rotation[2] for s in src.read())
        return float(np.percentile(spread, 90)), yaw

    free, free_yaw = heading_spread(False)
    held, _ = heading_spread(True)
    assert held < math.radians(15) < free and free_yaw == 0.0


def test_a_stall_is_held_once_logged_on_every_held_frame_with_the_rates_sent(sim):
    """Replies already in flight when ClearFaults goes out still carry the latched stall bit: they must not start
    a second hold. Every frame that sent Stop logs the stall bit and rates 0 (what was sent)."""
    src, clock, rows = sim
    link = src.loop.link
    sent = []  # (log row's frame, command) for Stop and ClearFaults

    def recorded(name):
        command = getattr(link, name)

        def record():
            sent.append((src.loop.frame + 1, name))
            return command()
        return record

    for name in ("stop", "clear_faults"):
        setattr(link, name, recorded(name))
    _run(src, clock, 0.5)
    src.rig.firmware.stalled[0] = True
    _run(src, clock, 0.02)
    src.rig.firmware.stalled[0] = False
    _run(src, clock, 0.4)
    stop_frames = {f for f, name in sent if name == "stop"}
    assert [name for _, name in sent].count("clear_faults") == 1
    assert len(stop_frames) <= round(src.loop.stall_hold_s * 700) + 3  # one hold of 0.1 s at 700 frames/s
    stall = 1 << FAULTS.index("stall")
    held = [r for r in rows if r[1] in stop_frames]
    assert len(held) == len(stop_frames) and all(r[-1] & stall and r[9:12] == (0.0, 0.0, 0.0) for r in held)
    assert rows[-1][-1] == 0 and math.hypot(*rows[-1][2:4]) < 2.0  # tracking again


@pytest.mark.parametrize("tether, counter_rotate", [("sideways", False), ("fixed", False), ("free_yaw", True)])
def test_a_tether_that_does_not_fit_counter_rotation_is_refused(tether, counter_rotate):
    with pytest.raises(ValueError, match="allowed: tether 'free_yaw' without counter_rotate, or 'fixed' with it"):
        open_source("servosphere", clock=SimulatedClock(), tether=tether, counter_rotate=counter_rotate)


@pytest.mark.parametrize("cfg, message", [
    ({"apex_px": [320, 240], "mm_per_px": 0.06, "rotaton_deg": 90},
     "unknown key 'rotaton_deg'; allowed: apex_px, mm_per_px, rotation_deg"),
    ({"apex_px": [320, 240]}, "needs mm_per_px; allowed: {apex_px, mm_per_px, \\[rotation_deg\\]} or {image"),
    ({"image": "calib.png", "mm_per_px": 0.06}, "unknown key 'mm_per_px'; allowed: disc_diameter_mm, image, rota"),
    ({"apex_px": [math.nan, 240], "mm_per_px": 0.06}, "apex_px must be 2 finite numbers"),
    ({"apex_px": [320, 240], "mm_per_px": 0.06, "rotation_deg": math.nan}, "rotation_deg must be a finite number"),
])
def test_calibration_settings_name_what_is_wrong(cfg, message):
    with pytest.raises(ValueError, match=message):
        _calibration(cfg)
