"""Servosphere robustness: fault bookkeeping across sequence-number wrap, firmware resets, a lost serial port,
the heading of an ant standing still, options that would be ignored."""

import dataclasses
import math

import numpy as np
import pytest

from antarium.core.ball import pole_motion
from antarium.core.clock import SimulatedClock
from antarium.locomotion import open_source
from antarium.locomotion.servosphere.firmware import FirmwareEmulator
from antarium.locomotion.servosphere.source import FAULTS

STALL = 1 << FAULTS.index("stall")


class Rows:
    def __init__(self):
        self.rows = []

    def add_servosphere(self, row):
        self.rows.append(row)


def _run(src, clock, seconds):
    for _ in range(int(round(seconds * 190))):
        clock.advance(1 / 190)
        src.read()


@pytest.fixture
def sim():
    clock = SimulatedClock()
    src = open_source("servosphere", clock=clock, simulation={"seed": 4, "speed": 0.05, "meander": 2.0})
    log = Rows()
    src.use_log(log)
    src.start()
    yield src, clock, log.rows
    src.stop()


def test_a_stall_long_after_the_last_clear_is_seen(sim):
    """The clear's seq is forgotten once its reply came: a stall 32,768+ commands (~47 s at 700 Hz) after a
    ClearFaults is still a stall (it used to be taken for a reply sent before the clear, and ignored)."""
    src, clock, rows = sim
    _run(src, clock, 0.3)
    src.rig.firmware.stalled[0] = True
    _run(src, clock, 0.02)
    src.rig.firmware.stalled[0] = False
    _run(src, clock, 0.3)  # hold, ClearFaults, control again
    assert rows[-1][-1] == 0
    link = src.loop.link
    for _ in range(32_800):  # as many commands as ~47 s of frames; the firmware answers every one
        link.send_rates(rows[-1][9:12])
    _run(src, clock, 0.1)
    n = len(rows)
    src.rig.firmware.stalled[1] = True
    _run(src, clock, 0.02)
    assert any(r[-1] & STALL for r in rows[n:])
    assert np.all(src.rig.firmware.rate == 0)


def _heading_run(seconds, **options):
    clock = SimulatedClock()
    sim = {"speed": 0.05, "meander": 2.0, "seed": 1, **options.pop("simulation", {})}
    src = open_source("servosphere", clock=clock, simulation=sim, **options)
    log = Rows()
    src.use_log(log)
    yaw = 0.0
    for _ in range(int(round(seconds * 190))):
        clock.advance(1 / 190)
        yaw += sum(abs(s.rotation[2]) for s in src.read())
    src.stop()
    return src, log.rows, yaw


def test_the_heading_holds_while_the_ant_stands_still():
    """Half the 0.5 s spurts are pauses: the head end is decided from the walk over ~80 ms with hysteresis, so a
    still ant's tracking noise and the ball settling never flip it (one frame's velocity flipped it ~200 times)."""
    src, rows, _ = _heading_run(6.0, simulation={"pause_fraction": 0.5})
    headings = np.array([r[5] for r in rows[100:]])
    assert np.all(np.isfinite(headings))
    flips = np.abs(np.remainder(np.diff(headings) + math.pi, math.tau) - math.pi) > math.pi / 2
    assert int(flips.sum()) == 0
    assert abs(math.remainder(headings[-1] - src.rig.ant_heading, math.tau)) < math.radians(10)


def test_no_yaw_is_commanded_before_the_walk_confirms_the_heading():
    """counter_rotate on an ant that never walks: its body axis is seen, but not which end is its head, so the yaw
    command stays 0 (the ball does not spin it round on a guess)."""
    _, rows, _ = _heading_run(0.5, counter_rotate=True, tether="fixed", simulation={"speed": 0.0})
    assert len(rows) > 300 and all(math.isfinite(r[5]) for r in rows[10:])  # tracked, a heading logged
    assert all(r[8] == 0.0 for r in rows)  # omega_z asked for


class RebootedFirmware(FirmwareEmulator):
    """The emulated firmware at rig time `t` (s), booted `uptime_s` before: step counts from 0 and its u32
    microsecond clock at `uptime_s`."""

    def __init__(self, limits, t, uptime_s=0.0):
        super().__init__(limits, t0=t)
        self.t_boot = t - uptime_s

    def status(self, seq):
        s = super().status(seq)
        return dataclasses.replace(s, t_us=int(round((self.t - self.t_boot) * 1e6)) % 2 ** 32)


@pytest.mark.parametrize("clock_restarts, uptime_s", [(True, 0.0), (False, 0.0), (True, 2400.0)],
                         ids=["clock_back", "clock_on", "clock_past_2_31"])
def test_a_firmware_reset_is_a_fault_not_a_rotation(sim, clock_restarts, uptime_s):
    """The counts fall back to 0 and the clock to 0 (it went back), or goes on (the counts jump), or falls to 0 from
    2.4e9 us, past 2^31: a forward step of 1.9e9 us mod 2^32, far more than the host time since the previous reply."""
    src, clock, rows = sim
    rig = src.rig
    rig.firmware = RebootedFirmware(rig.limits, rig.t, uptime_s)  # up for `uptime_s` when the run starts
    _run(src, clock, 1.0)
    before = rig.firmware.status(0)
    assert before.t_us == pytest.approx((uptime_s + 1.0) * 1e6, abs=1e4)
    assert max(abs(before.steps1), abs(before.steps2), abs(before.steps3)) > 200  # counts the reset loses
    rig.firmware = RebootedFirmware(rig.limits, rig.t) if clock_restarts else FirmwareEmulator(rig.limits, t0=rig.t)
    n = len(rows)
    moved = []
    for _ in range(190):
        clock.advance(1 / 190)
        moved += [math.hypot(*pole_motion(s.rotation, 0.06)[:2]) for s in src.read()]
    assert max(moved) < 1e-3  # m per sample; the reset used to arrive as one ~0.1 m step
    reset = 1 << FAULTS.index("firmware_reset")
    assert sum(1 for r in rows[n:] if r[-1] & reset) == 1 and src.status()["faults"]["firmware_reset"] == 1
    assert math.hypot(*rows[-1][2:4]) < 2.0  # still tracking


class FailingSerial:
    """pyserial's object under `SerialPort` (the lowest seam): relays to the simulated rig's line, then its writes
    time out (USB CDC not draining: pyserial raises SerialTimeoutException, an OSError)."""

    def __init__(self, rig_port, good_writes):
        self.rig_port, self.good_writes, self._pending = rig_port, good_writes, b""

    @property
    def in_waiting(self):
        self._pending = self.rig_port.read()
        return len(self._pending)

    def read(self, n):
        return self._pending

    def write(self, data):
        import serial

        self.good_writes -= 1
        if self.good_writes < 0:
            raise serial.SerialTimeoutException("Write timeout")
        self.rig_port.write(data)

    def close(self):
        pass


def test_a_serial_error_in_the_thread_is_reported_not_hidden():
    from antarium.core.clock import MonotonicClock
    from antarium.locomotion.servosphere.link import MAX_STALLED_WRITES, MotorLink, SerialPort

    src = open_source("servosphere", clock=MonotonicClock(), process=False, simulation={"seed": 1})
    port = SerialPort.__new__(SerialPort)
    port._serial = FailingSerial(src.rig.port, good_writes=100)
    src.loop.link = MotorLink(port)
    src.start()
    thread = src._thread
    thread.join(30.0)
    status = src.status()
    src.stop()
    assert not thread.is_alive()
    # a refused write drops its command; MAX_STALLED_WRITES in a row end the loop (the first one did until
    # 2026-11-27: tests/test_servosphere_link.py)
    # (and the Stop the failed loop sends is refused too)
    assert status["connected"] is False and status["link"]["stalled"] == MAX_STALLED_WRITES + 1
    assert status["error"] == (f"RuntimeError: the motor link's port took none of the last {MAX_STALLED_WRITES} "
                               "messages (serial write of 21 bytes not taken: Write timeout): the microcontroller "
                               "is not reading")
    assert status["frames"] == 100 + MAX_STALLED_WRITES - 1


def test_a_lost_serial_device_reaches_the_parent_of_the_servosphere_process(tmp_path):
    """pyserial's errors are OSErrors: the child must not take them for the pipe to its parent going away."""
    import socket
    import threading
    import time

    import cv2

    from antarium.locomotion.servosphere.process import ServosphereProcess
    from antarium.locomotion.servosphere.rig import SimulatedRig

    rig = SimulatedRig()
    video = str(tmp_path / "ant.avi")
    writer = cv2.VideoWriter(video, cv2.VideoWriter_fourcc(*"MJPG"), 700, (640, 480), False)
    for _ in range(2100):  # 3 s at 700 frames/s: the camera outlasts the serial device
        writer.write(rig.render())
    writer.release()
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(1)

    def device():  # accepts, then is unplugged
        conn, _ = server.accept()
        time.sleep(0.3)
        conn.close()

    threading.Thread(target=device, daemon=True).start()
    src = ServosphereProcess(camera="opencv", camera_index=video, link="serial",
                             port=f"socket://127.0.0.1:{server.getsockname()[1]}",
                             calibration={"apex_px": list(rig.calibration.apex_px),
                                          "mm_per_px": rig.calibration.mm_per_px})
    src.start()
    try:
        deadline = time.monotonic() + 30.0
        while src.status().get("error") is None and time.monotonic() < deadline:
            time.sleep(0.05)
        status = src.status()
    finally:
        src.stop()
        server.close()
    assert status["connected"] is False
    assert "Serial" in status["error"], status["error"]
