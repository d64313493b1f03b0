"""The motor link: one test class run against every back-end. `simulated` is the rig's firmware emulator behind
its simulated line; `serial` is pyserial on a pseudo-terminal whose other end runs the same firmware emulator
(the lowest seam: our encode/decode runs on both sides)."""

import math
import os
import select
import threading
import time

import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.locomotion.servosphere import MOTOR_LINKS, open_motor_link
from antarium.locomotion.servosphere import protocol as p
from antarium.locomotion.servosphere.firmware import FirmwareEmulator
from antarium.locomotion.servosphere.link import MotorLink
from antarium.locomotion.servosphere.rig import SimulatedRig


class PtyFirmware:
    """The firmware emulator answering on the master side of a pseudo-terminal, in wall time."""

    def __init__(self):
        self.master, self.slave = os.openpty()
        self.path = os.ttyname(self.slave)
        self.firmware = FirmwareEmulator(watchdog_s=1.0, t0=time.monotonic())
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self):
        while not self._stop.is_set():
            ready, _, _ = select.select([self.master], [], [], 0.01)
            now = time.monotonic()
            self.firmware.advance(now)
            if ready:
                reply = self.firmware.receive(os.read(self.master, 4096), now)
                if reply:
                    os.write(self.master, reply)

    def close(self):
        self._stop.set()
        self._thread.join(1.0)
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture(params=sorted(MOTOR_LINKS))
def backend(request):
    """(link, firmware emulator, wait(seconds))"""
    if request.param == "simulated":
        clock = SimulatedClock()
        rig = SimulatedRig(clock)
        rig.firmware.watchdog_s = 1.0

        def wait(seconds):
            clock.advance(seconds)
            rig.advance(clock.now())

        yield open_motor_link("simulated", rig=rig), rig.firmware, wait
        return
    pty = PtyFirmware()
    link = open_motor_link("serial", url=pty.path)
    yield link, pty.firmware, time.sleep
    link.close()
    pty.close()


def _replies(link, wait, n=1, timeout=2.0):
    out = []
    for _ in range(int(timeout / 0.01)):
        out += link.poll()
        if len(out) >= n:
            break
        wait(0.01)
    return out


class TestEveryLink:
    def test_rates_are_acknowledged_with_growing_step_counts(self, backend):
        link, _, wait = backend
        seq = link.send_rates([2000, -2000, 0])
        (status, steps0), = _replies(link, wait)
        assert status.seq == seq and status.faults == 0
        wait(0.2)
        link.send_rates([2000, -2000, 0])
        status, steps = _replies(link, wait)[-1]
        assert steps[0] > steps0[0] + 50 and steps[1] < steps0[1] - 50 and steps[2] == steps0[2]

    def test_stop_ramps_the_rotors_to_zero(self, backend):
        link, firmware, wait = backend
        link.send_rates([4000, 4000, 4000])
        _replies(link, wait)
        wait(0.1)
        link.stop()
        _replies(link, wait)
        wait(0.1)
        link.clear_faults()
        (_, a), = _replies(link, wait)
        wait(0.1)
        link.clear_faults()
        (_, b), = _replies(link, wait)
        assert np.array_equal(a, b)

    def test_a_stalled_rotor_is_a_latched_fault_that_clears(self, backend):
        link, firmware, wait = backend
        firmware.stalled[1] = True
        link.send_rates([1000, 1000, 1000])
        _replies(link, wait)
        wait(0.05)
        link.send_rates([1000, 1000, 1000])
        status, _ = _replies(link, wait)[-1]
        assert status.faults & p.FAULT_STALL_2 and not np.any(firmware.target)
        firmware.stalled[1] = False
        link.clear_faults()
        status, _ = _replies(link, wait)[-1]
        assert status.faults == 0

    def test_garbage_on_the_line_is_counted_not_misread(self, backend):
        link, firmware, wait = backend
        link.port.write(b"\xa5\x5a\x01\x01\x0e" + bytes(16))  # a SetRates with a bad CRC
        link.send_rates([0, 0, 0])
        status, _ = _replies(link, wait)[-1]
        assert status.faults & p.FAULT_BAD_MESSAGE and not np.any(firmware.target)


def test_step_counters_unwrap_across_int32():
    class Replay:
        def __init__(self, data):
            self.data = data

        def read(self):
            data, self.data = self.data, b""
            return data

    top = 2 ** 31 - 10
    wrapped = top + 30 - 2 ** 32
    link = MotorLink(Replay(p.encode(p.Status(1, 0, top, 0, 0, 0)) + p.encode(p.Status(2, 10, wrapped, 0, 0, 0))))
    (_, a), (_, b) = link.poll()
    assert b[0] - a[0] == 30


@pytest.mark.parametrize("rates", [[0.0, math.nan, 0.0], [math.inf, 0.0, 0.0], [1.0, 2.0]])
def test_rates_that_are_not_3_finite_numbers_are_refused_and_nothing_is_sent(rates):
    written = []
    link = MotorLink(type("Port", (), {"write": staticmethod(written.append)})())
    with pytest.raises(ValueError, match="motor link rates must be 3 finite numbers"):
        link.send_rates(rates)
    assert written == [] and link.sent == 0 and link.seq == 0


def test_the_watchdog_stops_the_rotors_when_it_expires_however_time_is_stepped():
    """16000 steps/s reached at 40 ms, the watchdog (50 ms) expires at 50 ms, a 40 ms ramp down: 800 steps."""
    def position(times):
        firmware = FirmwareEmulator()
        firmware.receive(p.encode(p.SetRates(1, 16000, 0, 0)), 0.0)
        for t in times:
            firmware.advance(t)
        assert firmware.faults == p.FAULT_WATCHDOG and not firmware.rate.any()
        return firmware.position[0]

    assert position([0.04, 0.10]) == pytest.approx(800.0)
    assert position([0.04 + 0.0005 * k for k in range(121)]) == pytest.approx(800.0)


def test_unknown_link_names_what_is_allowed():
    with pytest.raises(ValueError, match="allowed: serial, simulated"):
        open_motor_link("can")


def test_a_serial_port_that_does_not_take_a_write_drops_the_message_and_breaks_the_link_only_when_it_persists():
    """pyserial's write timeout (10 ms: the microcontroller is not reading, its buffer full) dropped one message
    but ended the servosphere loop for good ('SerialTimeoutException: Write timeout', seen on a loaded machine).
    Now a refused message is counted (`stalled`) and dropped; the link breaks only after MAX_STALLED_WRITES in a
    row. Nobody reads the pseudo-terminal's other end here until the test drains it."""
    from antarium.locomotion.servosphere.link import MAX_STALLED_WRITES

    master, slave = os.openpty()
    link = open_motor_link("serial", url=os.ttyname(slave))
    try:
        sent = 0
        while link.stalled == 0:  # fill the line's buffer
            link.send_rates((1000, -2000, 0))
            sent += 1
            assert sent < 100_000
        assert link.sent == sent - 1
        for _ in range(MAX_STALLED_WRITES - 2):  # stalls short of the limit: dropped, counted, no error
            link.send_rates((0, 0, 0))
        assert link.stalled == MAX_STALLED_WRITES - 1
        while select.select([master], [], [], 0.05)[0]:  # the device reads again
            os.read(master, 65536)
        link.send_rates((0, 0, 0))
        assert (link.sent, link.stalled) == (sent, MAX_STALLED_WRITES - 1)
        while link.stalled < MAX_STALLED_WRITES:  # fill it again: the run of stalls starts from 0
            link.send_rates((1000, -2000, 0))
        with pytest.raises(RuntimeError, match=f"took none of the last {MAX_STALLED_WRITES} messages"):
            for _ in range(MAX_STALLED_WRITES):
                link.send_rates((0, 0, 0))
    finally:
        link.close()
        os.close(master)
        os.close(slave)
