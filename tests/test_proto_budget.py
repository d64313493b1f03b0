"""The dome link's bit budget runs in code: 66 bytes of overhead a datagram, polariser updates where they fit."""

import math
from types import SimpleNamespace

import numpy as np
import pytest

from antarium.core.clock import SimulatedClock
from antarium.firmware_proto.budget import (
    FRAME_BITS,
    POLARISER_BITS,
    LinkBudget,
    max_frame_rate,
    max_rate_with_polarisers,
    wire_bits,
)
from antarium.locomotion import BallSample, LocomotionSource
from antarium.server.frame_loop import FrameLoop


def test_the_budget_counts_66_bytes_a_datagram_and_pads_the_latch():
    assert wire_bits(1112) == 8 * (1112 + 66)
    assert wire_bits(4) == 8 * 84                      # the spec's own 84-byte LATCH
    assert FRAME_BITS == 518_992 and POLARISER_BITS == 8 * (994 + 66)
    assert max_frame_rate() == pytest.approx(192.7, abs=0.05)
    assert max_frame_rate(extra_bits=POLARISER_BITS) == pytest.approx(189.6, abs=0.05)


def test_frames_beyond_the_link_are_refused():
    with pytest.raises(ValueError, match="at most 192.7 frames/s"):
        LinkBudget(200.0)


def test_above_the_polariser_limit_an_update_never_fits_and_below_it_one_does():
    """Between 191.1 and 192.7 frames/s the frames fit but no update ever would: `check_config` refuses those."""
    limit = max_rate_with_polarisers()
    assert limit == pytest.approx(100e6 / (FRAME_BITS + POLARISER_BITS / 2)) and 191.1 < limit < 191.2
    assert LinkBudget(limit - 0.01).update_fits()
    assert not LinkBudget(limit + 0.01).update_fits()
    assert limit + 0.01 < max_frame_rate()  # frames alone still fit there


def test_at_190_hz_an_update_every_frame_does_not_fit_and_is_deferred():
    budget, sent = LinkBudget(190.0), []
    for _ in range(700):
        ok = budget.update_fits()
        budget.period(ok)
        sent.append(ok)
        # the next frame always ends within its period
        assert budget.backlog + FRAME_BITS <= budget.period_bits + 1e-6
    share = np.mean(sent)
    assert 0.5 < share < 1.0 and budget.backlog >= 0
    # the sustained share is what the spare bits allow
    spare = budget.period_bits - FRAME_BITS
    assert share == pytest.approx(spare / POLARISER_BITS, abs=0.01)
    assert LinkBudget(150.0).update_fits()   # with room to spare every update goes out


class _Turning(LocomotionSource):
    """A fixed-tether ant turning every frame, so the sky's polariser angles change every frame."""

    def __init__(self, clock):
        self.clock, self.seq = clock, 0

    def read(self):
        self.seq += 1
        return [BallSample(self.clock.now(), self.seq, (0.0, 0.0, 0.01))]

    def status(self):
        return {"connected": True}


class _Link:
    def __init__(self):
        self.updates = 0
        self.counters = {"datagrams_failed": 0}  # the link's counters, as `Link` keeps them

    def send_frame(self, frame):
        return 0

    def send_polarisers(self, angles):
        self.updates += 1
        return True

    def telemetry(self, wait_s=0.0):
        return {}


class SkyRenderer:
    """A renderer with a sky: dark LED frames (20350, 2) uint16 and polariser angles (55, 9) rad of 0."""

    scene = SimpleNamespace(sky=object())
    last_timings: dict = {}

    def render(self, pose, out=None):
        return np.zeros((20350, 2), np.uint16)

    def polariser_angles(self):
        return np.zeros((55, 9))


def test_the_frame_loop_defers_polariser_updates_the_link_cannot_carry():
    clock = SimulatedClock()
    link = _Link()
    loop = FrameLoop(clock=clock, source=_Turning(clock), renderer=SkyRenderer(), link=link, tether="fixed",
                     rate_hz=190.0)
    loop.renderer_changed()
    for _ in range(380):
        loop.step()
    assert 190 < link.updates < 380 and loop.link_budget.deferred == 380 - link.updates
    assert not math.isnan(loop.link_budget.backlog)


def test_held_state_sent_again_after_a_reboot_counts_in_the_frames_budget():
    """A distributor that rebooted gets the dot correction, brightness and polarisers again (57 datagrams, 0.70 of a
    frame) inside one period: the budget's backlog holds them, so the next polariser updates wait behind them (they were
    sent beside the budget, which stayed at 0 while the next frames would have run late on a real line)."""
    from antarium.firmware_proto.config import encode_brightness, encode_dot_correction
    from antarium.firmware_proto.emulator import Emulator

    loop = loop_on_a_virtual_dome()
    link = loop.link
    assert loop.link_budget.backlog == 0.0 and link.counters["state_resent"] == 0
    link.emulator = Emulator()  # rebooted: its counters start again, its panels at 100 %
    backlog = []
    for _ in range(200):
        loop.step()
        backlog.append(loop.link_budget.backlog)
    resent = link.counters["state_resent_bits"]
    one_panel, brightness = encode_dot_correction(0, np.full(740, 50)), encode_brightness(40)
    assert link.counters["state_resent"] == 57  # the dot corrections, the brightness and the polarisers
    assert resent == 55 * wire_bits(len(one_panel)) + wire_bits(len(brightness)) + POLARISER_BITS
    assert (link.emulator.dot == 50).all()
    assert max(backlog) == pytest.approx(resent + FRAME_BITS - 100e6 / 190.0)


def loop_on_a_virtual_dome(clock: SimulatedClock | None = None) -> FrameLoop:
    """A frame loop at 190 frames/s with a sky, on a virtual dome given a dot correction (50 %) and brightness (40 %)
    (the state its link holds), after 40 frames."""
    from antarium.firmware_proto.link import open_link

    clock = clock or SimulatedClock()
    link = open_link("virtual", clock=clock)
    link.send_config(dot_correction=50, brightness=40)
    loop = FrameLoop(clock=clock, source=None, renderer=SkyRenderer(), link=link, rate_hz=190.0)
    for _ in range(40):
        loop.step()
    return loop
