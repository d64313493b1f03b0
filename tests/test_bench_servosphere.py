"""`antarium bench servosphere`'s control-loop figure: the host's side of a step is the step's time less the
simulated rig's (camera, physics, firmware emulator), each counted once, on a fake clock."""

from __future__ import annotations

import time

import pytest

from antarium.bench import servosphere as bench
from antarium.bench.servosphere import SimulatedTime


def test_a_call_within_a_timed_call_is_counted_once():
    now = [0.0]
    sim = SimulatedTime(clock=lambda: now[0])

    def deliver():
        now[0] += 1.0

    timed_deliver = sim.timed(deliver)

    def grab():  # the camera's grab advances the rig, which delivers
        now[0] += 2.0
        timed_deliver()
        return "frame"

    assert sim.timed(grab)() == "frame"
    timed_deliver()  # on its own, outside a grab
    assert sim.seconds == 4.0


def test_the_host_side_is_the_step_less_the_rig_counted_once(monkeypatch):
    from antarium.locomotion.servosphere.rig import SimulatedPort
    from antarium.locomotion.servosphere.tracker import Tracker

    now = [0.0]  # the fake clock: only the firmware emulator and the tracker take time
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])
    deliver, update = SimulatedPort.deliver, Tracker.update
    delivered = [0]

    def slow_deliver(self, t):
        now[0] += 1e-3
        delivered[0] += 1
        return deliver(self, t)

    def slow_update(self, *args, **kwargs):
        now[0] += 5e-3
        return update(self, *args, **kwargs)

    monkeypatch.setattr(SimulatedPort, "deliver", slow_deliver)
    monkeypatch.setattr(Tracker, "update", slow_update)
    lp = bench._loop(0.05)
    assert lp["steps"] > 0 and delivered[0] > lp["steps"]  # several sub-steps of the rig per camera frame
    assert lp["host_us_per_step"] == pytest.approx(5000.0)  # the tracker's 5 ms, the firmware's time not in it
    assert lp["whole_step_hz"] == pytest.approx(lp["steps"] / (lp["steps"] * 5e-3 + delivered[0] * 1e-3))
