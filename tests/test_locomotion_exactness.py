"""Locomotion must be exact and never silently lost: scale, replay timing, counted drops, cut lines, gaps,
samples measured before an unplug, refused wire payloads, duplicate USB reports."""

import socket
import threading
from types import SimpleNamespace

import pytest
from conftest import wait_for

from antarium.core.ball import pole_motion
from antarium.core.clock import SimulatedClock
from antarium.locomotion import BallSample, wire
from antarium.locomotion.bus import BusSource
from antarium.locomotion.fictrac.source import FicTracSource
from antarium.locomotion.replay import ReplaySource
from antarium.locomotion.scripted import ScriptedSource
from antarium.locomotion.trackball import calibration
from antarium.locomotion.trackball import config as tbconfig
from antarium.locomotion.trackball import protocol as P
from antarium.locomotion.trackball.driver import UsbTrackball
from antarium.locomotion.trackball.emulator import EmulatedTrackball, constant
from antarium.server.frame_loop import FrameLoop

R = 0.05
WALK = (0.0, -0.03 / R, 0.0)  # rad/s about the dome axes: the ant walks forward 0.03 m/s


def collect(src, n, timeout_s=10.0):
    out = []
    assert wait_for(lambda: len(out.extend(src.read()) or out) >= n, timeout_s)
    return out[:n]


def walked(samples):
    return sum(pole_motion(s.rotation, R)[0] for s in samples)


# --- 1: counts per mm follow the resolution -----------------------------------------------------------------
@pytest.mark.parametrize("cpi", [1200, 2400])
def test_usb_default_counts_per_mm_follow_the_resolution(cpi):
    backend = EmulatedTrackball(motion=constant(WALK), realtime=False)  # a lens at the nominal counts per mm
    with UsbTrackball(trackball={"resolution_cpi": cpi}, backend=backend) as src:
        samples = collect(src, 1000)
        status = src.status()
    assert walked(samples) == pytest.approx(0.03, abs=2e-5)
    assert status["resolution_cpi"] == cpi  # as GET_INFO says it was applied


class RoundingTrackball(EmulatedTrackball):
    """A sensor that rounds the asked resolution to its 100-cpi step (as the PMW3360 does)."""

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        if bmRequestType == P.REQUEST_TYPE_OUT and bRequest == P.REQ_SET_RESOLUTION:
            wValue = round(wValue / 100) * 100
        return super().ctrl_transfer(dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout)


def test_usb_nominal_counts_per_mm_use_the_resolution_the_device_applied():
    backend = RoundingTrackball(motion=constant(WALK), realtime=False)
    with UsbTrackball(trackball={"resolution_cpi": 1240}, backend=backend) as src:
        samples = collect(src, 1000)
        status = src.status()
    assert walked(samples) == pytest.approx(0.03, abs=2e-5)
    assert status["resolution_cpi"] == 1200


def test_a_calibration_records_its_resolution_and_another_resolution_is_refused(tmp_path):
    config = tbconfig.TrackballConfig(resolution_cpi=2400)
    steps = [calibration.Step(a, 2.0, tuple(int(round(c * 1e3 * 90.0)) for c in
                                            calibration.predicted_travel(config, a, 2.0))) for a in "zxy"]
    result = calibration.calibrate(config, steps)
    assert [s.calibration_cpi for s in result.config.sensors] == [2400, 2400]
    assert result.config.sensors[0].counts_per_mm[0] == pytest.approx(90.0, rel=1e-3)
    rig = tmp_path / "rig.toml"
    rig.write_text("[trackball]\nresolution_cpi = 2400   # kept\n")
    assert tbconfig.write_section(rig, result.config) is None
    assert tbconfig.load(rig) == result.config
    rig.write_text(rig.read_text().replace("resolution_cpi = 2400", "resolution_cpi = 1200"))
    with pytest.raises(tbconfig.TrackballConfigError,
                       match=r"^\[\[trackball.sensors\]\] #0 counts_per_mm were calibrated at calibration_cpi = 2400 "
                             r"but \[trackball\] resolution_cpi = 1200: set resolution_cpi = 2400 or calibrate "
                             r"again \(antarium trackball calibrate\)$"):
        tbconfig.load(rig)


# --- 2: a replayed trial log drives the loop as the original did ----------------------------------------------
def test_replay_of_a_trial_log_gives_the_original_frames(tmp_path):
    from antarium.trial_log import TrialLog

    def run(source, clock, log=None, n=400):
        loop = FrameLoop(clock=clock, source=source, rate_hz=190, tether="fixed", log=log)
        return [(r.pose.x, r.pose.y, r.pose.heading, r.sample_seq) for r in (loop.step() for _ in range(n))]

    clock = SimulatedClock(start=100.0)
    path = tmp_path / "trial.h5"
    with TrialLog(path, {}, "orig") as log:
        original = run(ScriptedSource(speed=0.03, turn_rate=0.8, meander=1.0, tether="fixed", rate_hz=1000,
                                      clock=clock), clock, log)
    clock = SimulatedClock(start=100.0)
    replayed = run(ReplaySource(str(path), clock=clock), clock)
    assert original[0][3] == -1 and original[-1][3] > 0  # no sample in the first frame: the source started late
    assert replayed == original  # exact: same clock readings, offsets from the same trial start


# --- 3 / 6: FicTrac: queue drops and cut TCP lines are counted -----------------------------------------------
def fictrac_line(n, cut=False):
    text = "FT, " + ", ".join([str(n)] + ["0.001"] * 20 + [str(1.7e12 + n * 10), str(n), "10", "1000"]) + "\n"
    return text.encode()[: len(text) // 2] if cut else text.encode()


def test_fictrac_udp_counts_samples_dropped_from_a_full_queue():
    src = FicTracSource(transport="udp", port=0, max_queue=5)
    src.start()
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for n in range(1, 21):
            tx.sendto(fictrac_line(n), src.address)
        assert wait_for(lambda: src.status()["lines"] == 20, 5.0)
        got = src.read()
        status = src.status()
    finally:
        src.stop()
        tx.close()
    assert [s.seq for s in got] == [16, 17, 18, 19, 20]
    assert status["dropped_samples"] == 15 and status["frames"] == 20


def test_fictrac_tcp_line_cut_by_the_disconnect_is_counted_malformed():
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def peer():
        conn, _ = server.accept()
        conn.sendall(fictrac_line(1) + fictrac_line(2) + fictrac_line(3, cut=True))
        conn.close()

    threading.Thread(target=peer, daemon=True).start()
    src = FicTracSource(transport="tcp", port=server.getsockname()[1], retry_s=5.0)
    src.start()
    try:
        assert wait_for(lambda: src.status()["malformed"] == 1, 5.0)
        got = src.read()
        status = src.status()
    finally:
        src.stop()
        server.close()
    assert [s.seq for s in got] == [1, 2]
    assert status["lines"] == 3 and status["frames"] == 2
    assert status["last_error"].startswith("FicTrac line cut by disconnect")


# --- 4 / 7: the bus source counts drops, gaps, resets and refuses unknown flag bits ---------------------------
def zenoh_sample(payload):
    return SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: payload, to_string=lambda: payload.decode()))


def test_bus_source_counts_dropped_samples_gaps_and_resets():
    src = BusSource(max_pending=10)
    for seq in [*range(0xFFFFFFF0, 0xFFFFFFFE), 1, 2, 50, 51, 3, 4]:
        src._on_sample(zenoh_sample(wire.encode(BallSample(0.0, seq, (0.0, -0.001, 0.0)))))
    got = src.read()
    status = src.status()
    assert [s.seq for s in got] == [0xFFFFFFFA, 0xFFFFFFFB, 0xFFFFFFFC, 0xFFFFFFFD, 1, 2, 50, 51, 3, 4]
    assert status["received"] == 20 and status["dropped_samples"] == 10
    # 0xFFFFFFFD -> 1 across the wrap: 3 lost; 2 -> 50: 47 lost; 51 -> 3: a step back
    assert status["gaps"] == 2 and status["lost_samples"] == 3 + 47
    assert status["seq_resets"] == 1


@pytest.mark.parametrize("offset, value, match", [(1, 0x03, "flags 0x03 set unknown bits"),
                                                  (2, 0x01, "reserved field must be 0")])
def test_wire_refuses_unknown_flag_bits_and_reserved_bytes(offset, value, match):
    payload = bytearray(wire.encode(BallSample(1.0, 1, (0.0, 0.0, 0.0), 2.0, 1.0)))
    payload[offset] = value
    with pytest.raises(wire.LocomotionWireError, match=match):
        wire.decode(bytes(payload), 0.0)
    src = BusSource()
    src._on_sample(zenoh_sample(bytes(payload)))
    assert src.read() == [] and src.status()["malformed"] == 1


@pytest.mark.parametrize("quality", [7.5, -3.0, 1.0001])
def test_wire_refuses_a_quality_outside_0_to_1(quality):
    payload = wire.encode(BallSample(1.0, 1, (0.0, 0.0, 0.0), 2.0, quality))
    with pytest.raises(wire.LocomotionWireError, match=r"quality must be in \[0, 1\], got "):
        wire.decode(payload, 0.0)
    src = BusSource()
    src._on_sample(zenoh_sample(payload))
    assert src.read() == [] and src.status()["malformed"] == 1
    assert [wire.decode(wire.encode(BallSample(1.0, 1, (0.0,) * 3, 2.0, q)), 0.0).quality for q in (0.0, 1.0)] == [
        0.0, 1.0]


@pytest.mark.parametrize("rotation", [(1e300, 0.0, 0.0), (0.0, -1000.5, 0.0), (0.0, 0.0, 2e3)])
def test_wire_refuses_a_rotation_beyond_any_balls_motion_in_one_sample(rotation):
    payload = wire.encode(BallSample(1.0, 1, rotation, 2.0, 1.0))
    with pytest.raises(wire.LocomotionWireError, match=r"is beyond any ball's motion in one sample \(allowed: each "
                                                        r"within \+-1000 rad\)"):
        wire.decode(payload, 0.0)
    src = BusSource()
    src._on_sample(zenoh_sample(payload))
    assert src.read() == [] and src.status()["malformed"] == 1
    turn = (wire.MAX_ROTATION_RAD, -wire.MAX_ROTATION_RAD, 20.0)  # a 2 cm step on a 1 mm ball is 20 rad
    assert wire.decode(wire.encode(BallSample(1.0, 1, turn, 2.0, 1.0)), 0.0).rotation == turn


# --- 7: a duplicate USB report is dropped and counted, its motion counted once ---------------------------------
def test_usb_duplicate_report_is_dropped_and_counted():
    backend = EmulatedTrackball(motion=constant(WALK), realtime=False, faults={100: "duplicate"})
    with UsbTrackball(backend=backend) as src:
        samples = collect(src, 1000)
        status = src.status()
    assert [s.seq for s in samples] == list(range(1000))
    assert status["duplicate_reports"] == 1 and status["seq_resets"] == 0 and status["gaps"] == 0
    assert walked(samples) == pytest.approx(0.03, abs=2e-5)


# --- 5: samples measured before an unplug move the pose -------------------------------------------------------
def test_samples_measured_before_an_unplug_are_integrated():
    backend = EmulatedTrackball(motion=constant(WALK), realtime=False, faults={200: "unplug"})
    src = UsbTrackball(backend=backend, retry_s=10.0)
    src.start()
    try:
        assert wait_for(lambda: not src.status()["connected"] and src.counters["reports"] == 200, 5.0)
        assert src.status()["last_seq"] == 199
        loop = FrameLoop(clock=SimulatedClock(), source=src, rate_hz=190)
        rec = loop.step()
    finally:
        src.stop()
    assert not rec.locomotion_connected and loop.samples_used == 200 and rec.sample_seq == 199
    assert loop.pose.x == pytest.approx(200 * 0.03 / 1000, abs=3e-5)  # as a replay of the log moves it (±1 count)

