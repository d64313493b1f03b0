"""The distributor/panel emulator: latch rule under loss and reordering, settings, faults, actuators, heat."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.core.clock import SimulatedClock
from antarium.firmware_proto import config, control, led_driver, polariser, video
from antarium.firmware_proto.actuator import AircoreBank
from antarium.firmware_proto.emulator import Emulator
from antarium.firmware_proto.link import open_link
from antarium.firmware_proto.replies import decode_reply

BASE = 1000


def tag_frame(k: int) -> np.ndarray:
    """A frame whose every LED 0 is BASE + k and LED 1 is 0 (decodes exactly): panels show which frame they hold."""
    f = np.zeros((20350, 2), np.uint16)
    f[:, 0] = BASE + k
    return f


def shown_tags(emu: Emulator) -> np.ndarray:
    """(55,) the frame tag each panel shows (-BASE: nothing latched yet); asserts the panel is uniform."""
    v = emu.led_values().reshape(55, 370, 2).astype(np.int64)
    assert (v == v[:, :1, :]).all(), "a panel shows a mix of two frames"
    return v[:, 0, 0] - BASE


def datagrams(k: int, seq: int | None = None) -> list[bytes]:
    return [row.tobytes() for row in video.encode_frame(tag_frame(k), seq=k % 128 if seq is None else seq)]


def latch(k: int) -> bytes:
    return control.encode_latch(k % 128)


@pytest.fixture
def emu():
    return Emulator(clock=SimulatedClock())


class TestLatchRule:
    def test_nothing_changes_before_the_latch(self, emu):
        for d in datagrams(1):
            emu.handle_datagram(d)
        assert (shown_tags(emu) == -BASE).all()
        emu.handle_datagram(latch(1))
        assert (shown_tags(emu) == 1).all()
        assert emu.counters["frames_latched"] == 1 and emu.counters["frames_dropped"] == 0

    def test_lost_datagram_keeps_that_panel_on_its_previous_image(self, emu):
        for d in datagrams(1) + [latch(1)]:
            emu.handle_datagram(d)
        for d in [d for d in datagrams(2) if d[0] != 7] + [latch(2)]:
            emu.handle_datagram(d)
        tags = shown_tags(emu)
        assert tags[7] == 1 and (np.delete(tags, 7) == 2).all()
        assert emu.counters["frames_dropped"] == 1 and emu.counters["panel_misses"] == 1
        for d in datagrams(3) + [latch(3)]:
            emu.handle_datagram(d)
        assert (shown_tags(emu) == 3).all()

    def test_lost_latch_drops_the_whole_frame(self, emu):
        for d in datagrams(1) + [latch(1)] + datagrams(2):  # latch 2 lost
            emu.handle_datagram(d)
        assert (shown_tags(emu) == 1).all()
        for d in datagrams(3) + [latch(3)]:
            emu.handle_datagram(d)
        assert (shown_tags(emu) == 3).all()
        assert emu.counters["superseded"] == 55 and emu.counters["frames_latched"] == 2

    def test_late_datagram_after_its_latch_is_stale(self, emu):
        early, late = datagrams(1)[:54], datagrams(1)[54]
        for d in early + [latch(1), late]:
            emu.handle_datagram(d)
        assert shown_tags(emu)[54] == -BASE and emu.counters["rejected_stale"] == 1
        for d in datagrams(2)[::-1] + [latch(2)]:
            emu.handle_datagram(d)
        assert (shown_tags(emu) == 2).all()

    def test_next_frame_before_this_latch(self, emu):
        # datagram of frame 2 for panel 0 overtakes the latch of frame 1
        d1, d2 = datagrams(1), datagrams(2)
        for d in d1 + [d2[0], latch(1)]:
            emu.handle_datagram(d)
        tags = shown_tags(emu)
        assert tags[0] == -BASE and (tags[1:] == 1).all()
        for d in d2[1:] + [latch(2)]:
            emu.handle_datagram(d)
        assert (shown_tags(emu) == 2).all()

    def test_older_datagram_does_not_replace_a_newer_pending_one(self, emu):
        for d in [datagrams(3)[5], datagrams(2)[5], latch(3)]:
            emu.handle_datagram(d)
        assert shown_tags(emu)[5] == 3 and emu.counters["rejected_stale"] == 1

    def test_sequence_wraps(self, emu):
        for k in range(300):
            for d in datagrams(k) + [latch(k)]:
                emu.handle_datagram(d)
        assert (shown_tags(emu) == 299).all() and emu.counters["frames_latched"] == 300

    def test_immediate_flag_shows_on_receipt(self, emu):
        row = video.encode_frame(tag_frame(9), seq=0, immediate=True)[4].tobytes()
        emu.handle_datagram(row)
        assert shown_tags(emu)[4] == 9 and emu.counters["immediate"] == 1

    @settings(max_examples=60, deadline=None)
    @given(st.data())
    def test_random_loss_and_reordering(self, data):
        """Whatever is lost or reordered: panels show whole images, only of latched frames, never going back."""
        emu = Emulator(clock=SimulatedClock())
        n = data.draw(st.integers(1, 6))
        first = data.draw(st.integers(1, 130))  # sequences 1..127 and across the wrap to 0
        events = []
        for k in range(first, first + n):
            events += [("d", k, p) for p in range(55)] + [("l", k, None)]
        keep = data.draw(st.lists(st.booleans(), min_size=len(events), max_size=len(events)))
        events = [e for e, kept in zip(events, keep, strict=True) if kept or data.draw(st.booleans())]
        # local reordering: swap neighbours a few times
        for i in data.draw(st.lists(st.integers(0, max(0, len(events) - 2)), max_size=30)):
            if len(events) > 1:
                events[i], events[i + 1] = events[i + 1], events[i]
        rows = {k: datagrams(k) for k in range(first, first + n)}
        latched: set[int] = set()
        previous = shown_tags(emu)
        for kind, k, p in events:
            emu.handle_datagram(rows[k][p] if kind == "d" else latch(k))
            if kind == "l":
                latched.add(k)
            tags = shown_tags(emu)
            assert all(t == -BASE or t in latched for t in tags)
            assert (tags >= previous).all()
            previous = tags


class TestSettings:
    def test_dot_correction_and_brightness(self):
        rng = np.random.default_rng(3)
        with open_link("virtual", clock=SimulatedClock()) as link:
            f = np.zeros((20350, 2), np.uint16)
            f[:, 0] = rng.integers(0, 65536, 20350)
            dot = rng.integers(0, 101, (55, 740))
            link.send_config(dot_correction=dot, brightness=60)
            link.send_frame(f)
            expected = (f.reshape(55, 740).astype(np.int64) * dot * 60 + 5000) // 10000
            assert np.array_equal(link.emulator.led_values().reshape(55, 740), expected)
            link.send_config(dot_correction=100, brightness=100)  # takes effect at once, no new frame
            assert np.array_equal(link.emulator.led_values(), f)

    def test_config_accepts_frame_layout(self):
        with open_link("virtual", clock=SimulatedClock()) as link:
            dot = np.full((20350, 2), 100)
            dot[370 * 4 + 361, 1] = 0  # polarised UV LED of panel 4, UV slot 0
            link.send_config(dot_correction=dot)
            f = np.zeros((20350, 2), np.uint16)
            f[:] = [1550, 1000]  # L = 2550: C = 155 (GB) or 100 (UV) decodes exactly
            link.send_frame(f)
            v = link.emulator.led_values()
            assert v[370 * 4 + 361].tolist() == [1550, 0] and v[370 * 4 + 362].tolist() == [1550, 1000]
            assert np.array_equal(np.delete(v, 370 * 4 + 361, axis=0), np.delete(f, 370 * 4 + 361, axis=0))

    @pytest.mark.parametrize("kwargs, match", [
        ({"dot_correction": 101}, "allowed 0..100"),
        ({"dot_correction": np.zeros((55, 739))}, "shape"),
        ({"brightness": -1}, "allowed 0..100"),
    ])
    def test_bad_config_is_refused_before_sending(self, kwargs, match):
        with open_link("virtual", clock=SimulatedClock()) as link:
            before = dict(link.counters)
            with pytest.raises(ValueError, match=match):
                link.send_config(**kwargs)
            assert link.counters == before


class TestFaults:
    def test_open_led_is_dark_and_reported_once_driven(self):
        clock = SimulatedClock()
        with open_link("virtual", clock=clock) as link:
            link.emulator.inject_fault(3, 120, "open")
            link.emulator.inject_fault(3, 121, "short")
            f = np.zeros((20350, 2), np.uint16)
            link.send_frame(f)
            assert link.telemetry()["faults"] == []  # dark LEDs: the driver cannot detect anything
            f[370 * 3 + 60] = [5000, 6000]  # local 60 -> LEDs 120 (green) and 121 (blue)
            link.send_frame(f)
            assert link.emulator.led_values()[370 * 3 + 60].tolist() == [0, 0]
            t = link.telemetry()
            assert t["faults"] == [{"panel": 3, "led": 120, "kind": "open"}, {"panel": 3, "led": 121, "kind": "short"}]
            assert t["fault_total"] == 2
            link.send_frame(np.zeros((20350, 2), np.uint16))
            assert link.telemetry()["fault_total"] == 2  # detection is sticky

    def test_a_fault_that_changes_kind_is_reported_as_the_latest_kind(self):
        """Open, then short without "none" between: the LED was reported as neither (until 2026-11-27)."""
        with open_link("virtual", clock=SimulatedClock()) as link:
            f = np.zeros((20350, 2), np.uint16)
            f[:, 0] = 30000
            link.send_frame(f)
            link.emulator.inject_fault(3, 120, "open")
            assert link.telemetry()["faults"] == [{"panel": 3, "led": 120, "kind": "open"}]
            link.emulator.inject_fault(3, 120, "short")
            t = link.telemetry()
            assert t["faults"] == [{"panel": 3, "led": 120, "kind": "short"}] and t["fault_total"] == 1
            link.send_frame(np.zeros((20350, 2), np.uint16))
            link.emulator.inject_fault(3, 120, "open")  # not driven now: the driver cannot see the new kind
            assert link.telemetry()["faults"] == [{"panel": 3, "led": 120, "kind": "short"}]  # sticky
            link.emulator.inject_fault(3, 120, "none")
            assert link.telemetry()["fault_total"] == 0

    def test_bad_fault_spec(self, emu):
        with pytest.raises(ValueError, match="allowed"):
            emu.inject_fault(0, 0, "melted")
        with pytest.raises(ValueError, match="out of range"):
            emu.inject_fault(55, 0, "open")


class TestLedDriver:
    @pytest.mark.parametrize("v", [0, 1, 31, 32, 33, 1000, 65535])
    def test_waveform_on_time_and_spread(self, v):
        w = led_driver.pwm_waveform(v).reshape(32, 2048)
        assert w.sum() == v
        lit_segments = w.any(axis=1).sum()
        assert lit_segments == (32 if v >= 32 else v)

    def test_flicker_frequencies(self):
        f = led_driver.flicker_frequency_hz(np.array([0, 1, 31, 32, 65535]))
        assert f[0] == 0 and f[1] == f[2] == pytest.approx(305.18, abs=0.01)
        assert f[3] == f[4] == pytest.approx(9765.6, abs=0.1) and f[3] > 9000

    def test_flicker_reported_for_what_the_dome_shows(self, emu):
        for d in datagrams(0) + [latch(0)]:
            emu.handle_datagram(d)
        f = emu.flicker_frequency_hz()
        assert f.shape == (20350, 2) and (f[:, 0] > 9000).all() and (f[:, 1] == 0).all()


class TestActuators:
    def test_half_turn_settles_within_200_ms(self):
        bank = AircoreBank((1,))
        bank.command_rotor(0.0, np.pi)
        t = np.linspace(0.0, 0.3, 301)
        err = np.array([abs(bank.rotor_angle(x)[0] - np.pi) for x in t])
        settled = t[np.flatnonzero(err > np.radians(1.0)).max() + 1]
        assert settled < 0.2
        assert err[t >= 0.2].max() < np.radians(0.1)

    def test_polariser_turns_the_short_way_and_reports_angles(self):
        clock = SimulatedClock()
        with open_link("virtual", clock=clock) as link:
            target = np.full((55, 9), 3.0)  # from 0: 3.0 rad == -0.14 rad modulo pi
            target[0, 0] = 1.0
            link.send_polarisers(target)
            clock.advance(0.01)
            a = link.emulator.actuators.rotor_angle(clock.now())
            assert a[1, 1] < 0 and a[0, 0] > 0  # 3.0 is reached by turning back through 0
            clock.advance(0.25)
            t = link.telemetry()
            got = np.radians(t["polariser_angles_deg"])
            assert np.abs(np.angle(np.exp(2j * (got - target)))).max() / 2 < np.radians(0.2)
            assert not np.array(t["holding"]).any()
            clock.advance(1.0)
            assert np.array(link.telemetry()["holding"]).all()

    def test_a_panel_whose_status_is_lost_reports_the_power_up_state(self):
        """Every PANEL_STATUS lost on the line: ACTUATORS reports the power-up state, angle code 0 on holding
        current (docs/protocol.md section 5), not holding bits 0 (until 2026-11-27)."""
        def corrupt(symbols):
            if symbols.size == 16 * (8 + 2 + 210 + 2):  # a PANEL_STATUS frame: one data bit flipped, bad CRC
                symbols = symbols.copy()
                symbols[200:202] ^= 1
            return symbols

        emu = Emulator(clock=SimulatedClock(), line="bits", corrupt=corrupt)
        replies = [decode_reply(r) for r in emu.handle_datagram(control.encode_status_request(1))]
        assert emu.counters["rejected_crc"] == 55
        actuators = replies[3].fields
        assert np.array(actuators["holding"]).all() and not np.array(actuators["angle_codes"]).any()
        assert emu.actuators.holding(emu.clock.now()).all()  # as the actuators are

    def test_holding_current_is_a_quarter(self):
        bank = AircoreBank((2,))
        bank.command_rotor(0.0, np.array([0.5, 0.0]), mask=np.array([True, False]))
        assert bank.coil_current_a(0.1)[0] == pytest.approx(0.054)
        assert bank.coil_current_a(2.0)[0] == pytest.approx(0.054 / 4)
        s, c = bank.coil_currents_a(0.1)
        assert np.hypot(s, c)[0] == pytest.approx(0.054) and np.arctan2(s, c)[0] == pytest.approx(0.5)

    def test_unchanged_angles_are_not_resent(self):
        with open_link("virtual", clock=SimulatedClock()) as link:
            a = np.full((55, 9), 0.5)
            assert link.send_polarisers(a) and not link.send_polarisers(a) and link.send_polarisers(a, force=True)
            with pytest.raises(ValueError, match=r"\(55, 9\)"):
                link.send_polarisers(np.zeros((55, 8)))


class TestHeat:
    def test_full_white_panel_current_and_steady_temperature(self):
        clock = SimulatedClock()
        with open_link("virtual", clock=clock) as link:
            f = np.zeros((20350, 2), np.uint16)
            f[:370, 0] = 65535  # panel 0: every pixel at one LED's full current
            link.send_frame(f)
            t = link.telemetry()
            assert t["current_a"][0] == pytest.approx(370 * 0.020 + 47 * 0.030, abs=0.002)
            assert t["current_a"][1] == pytest.approx(47 * 0.030, abs=0.002)
            clock.advance(3000.0)  # ten time constants
            t = link.telemetry()
            coils = 9 * 0.054 / 4 * 12.0  # actuators at angle 0 on holding current: cos coil only
            power = 4.2 * (370 * 0.020 + 47 * 0.030) + coils
            assert t["temperature_c"][0] == pytest.approx(22.0 + 1.2 * power, abs=0.1)
            assert 22.0 < t["temperature_c"][1] < t["temperature_c"][0]


def test_fast_and_bit_exact_lines_give_identical_results():
    rng = np.random.default_rng(5)
    fast, bits = Emulator(clock=SimulatedClock(), line="fast"), Emulator(clock=SimulatedClock(), line="bits")
    stream = []
    for k in range(4):
        f = rng.integers(0, 30000, (20350, 2)).astype(np.uint16)
        rows = [r.tobytes() for r in video.encode_frame(f, seq=k)]
        stream += [rows[i] for i in rng.permutation(55)[:50]] + [latch(k)]
    stream += [config.encode_dot_correction(2, rng.integers(0, 101, 740)), config.encode_brightness(70),
               polariser.encode_polarisers(rng.uniform(0, np.pi, (55, 9))), b"\x37" * 1112, b"\x7f\x01\x01"]
    for d in stream:
        fast.handle_datagram(d)
        bits.handle_datagram(d)
    assert np.array_equal(fast.led_values(), bits.led_values())
    assert fast.stats() == bits.stats()
    assert fast.handle_datagram(control.encode_status_request(1)) == bits.handle_datagram(
        control.encode_status_request(1))


def test_corrupted_panel_links_lose_frames_but_never_mix_them():
    rng = np.random.default_rng(6)

    def corrupt(symbols):
        if rng.random() < 0.3:
            symbols = symbols.copy()
            i = rng.integers(symbols.size)
            symbols[i: i + rng.integers(1, 3)] ^= 1
        return symbols

    emu = Emulator(clock=SimulatedClock(), line="bits", corrupt=corrupt)
    for k in range(1, 8):
        for d in datagrams(k) + [latch(k)]:
            emu.handle_datagram(d)
        tags = shown_tags(emu)
        assert ((tags == -BASE) | ((tags >= 1) & (tags <= k))).all()
    s = emu.stats()
    assert s["rejected_manchester"] + s["rejected_crc"] > 0 and s["internal_errors"] == 0
    assert s["panel_misses"] > 0


def test_restarted_host_loses_at_most_one_frame(emu):
    for k in range(1, 40):
        for d in datagrams(k) + [latch(k)]:
            emu.handle_datagram(d)
    for d in datagrams(40):  # the old host dies before latching frame 40: it stays pending
        emu.handle_datagram(d)
    for k in (0, 1, 2):  # a new host starts again at sequence 0
        for d in datagrams(100 + k, seq=k) + [latch(k)]:
            emu.handle_datagram(d)
        assert (shown_tags(emu) != 40).all()  # the dead host's frame never appears
    assert (shown_tags(emu) == 102).all()
    assert emu.counters["frames_dropped"] == 1  # frame 0 only
