"""Datagram formats: golden byte vectors, encode/decode pairs, typed errors, the luminance/chromaticity error."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.firmware_proto import config, control, polariser, replies, video
from antarium.firmware_proto.errors import (
    FieldRangeError,
    LengthError,
    PanelError,
    ProtocolError,
    UnknownTypeError,
    VersionError,
)
from antarium.firmware_proto.header import seq_newer

PANEL = 2
G0 = PANEL * 370  # global index of local pixel 0 of panel 2


def worked_example_frame() -> np.ndarray:
    """The frame of docs/protocol.md's worked example."""
    f = np.zeros((20350, 2), np.uint16)
    f[G0 + 0] = [1000, 3000]      # green/blue
    f[G0 + 1] = [65535, 0]
    f[G0 + 360] = [0, 40000]
    f[G0 + 361] = [4660, 256]     # UV: plain, polarised
    return f


def random_frame(rng) -> np.ndarray:
    lum = rng.integers(0, 65536, 20350)
    first = (rng.random(20350) * (lum + 1)).astype(np.int64).clip(0, lum)
    return np.stack([first, lum - first], axis=1).astype(np.uint16)


class TestVideoGolden:
    def test_worked_example_bytes(self):
        d = video.encode_frame(worked_example_frame(), seq=5)[PANEL].tobytes()
        assert len(d) == 1112
        assert d[:14] == bytes.fromhex("02 05 0f a0 40 ff ff ff 00 00 00 00 00 00")
        assert d[1082:1094] == bytes.fromhex("9c 40 00 13 34 0d 00 00 00 00 00 00")
        assert d[1094:] == bytes(18)

    def test_whole_frame_digest(self):
        # pins every byte of all 55 datagrams of the worked example
        out = video.encode_frame(worked_example_frame(), seq=5)
        assert hashlib.sha256(out.tobytes()).hexdigest() == (
            "b9b9b5b802d7240682ecfd1c1d66f5993bfa3e77da22dd0efba399efd6f7ab97"
        )
        assert list(out[:, 0]) == list(range(55)) and set(out[:, 1]) == {5}

    def test_immediate_flag_and_parse(self):
        d = video.encode_frame(worked_example_frame(), seq=127, immediate=True)[54].tobytes()
        assert d[:2] == bytes([0x36, 0xFF])
        assert video.parse_video(d) == (54, 127, True)

    def test_decode_worked_example(self):
        f = worked_example_frame()
        back = video.decode_frame(video.encode_frame(f, seq=5))
        assert back[G0 + 1].tolist() == [65535, 0] and back[G0 + 360].tolist() == [0, 40000]
        assert back[G0].tolist() == [1004, 2996]          # C = 64: 4000 * 64 / 255 = 1003.9
        assert back[G0 + 361].tolist() == [4665, 251]  # C = 13: 4916 * 13 / 255 = 250.6 -> 251, 4916 - 251
        assert np.count_nonzero(back) == np.count_nonzero(f)


class TestLumaChroma:
    def test_error_bound_random(self):
        rng = np.random.default_rng(1)
        for _ in range(20):
            f = random_frame(rng)
            back = video.decode_frame(video.encode_frame(f, seq=0)).astype(np.int64)
            err = np.abs(back - f).max(axis=1)
            assert (err <= f.sum(axis=1, dtype=np.int64) / 510 + 0.5).all()
            assert (back.sum(axis=1) == f.sum(axis=1, dtype=np.int64)).all()  # luminance is exact

    def test_error_bound_exhaustive_small_luminance(self):
        # every (share, other) pair with L <= 600
        lum = np.repeat(np.arange(601), np.arange(601) + 1)
        share = np.concatenate([np.arange(n + 1) for n in range(601)])
        l32, c = video.luma_chroma(share.astype(np.uint16), (lum - share).astype(np.uint16))
        s, o = video.split_luma_chroma(l32, c)
        assert (np.abs(s.astype(np.int64) - share) <= lum / 510 + 0.5).all()
        assert (s.astype(np.int64) + o == lum).all()

    @settings(max_examples=500, deadline=None)
    @given(st.integers(0, 65535), st.data())
    def test_error_bound_property(self, lum, data):
        share = data.draw(st.integers(0, lum))
        l32, c = video.luma_chroma(np.array([share], np.uint16), np.array([lum - share], np.uint16))
        s, o = video.split_luma_chroma(l32, c)
        assert abs(int(s[0]) - share) <= lum / 510 + 0.5
        assert abs(int(o[0]) - (lum - share)) <= lum / 510 + 0.5

    def test_bound_is_nearly_reached(self):
        # the worst case over all shares at full luminance is within one LSB of L/510 (the bound is tight)
        share = np.arange(65536, dtype=np.uint16)
        l32, c = video.luma_chroma(share, (65535 - share).astype(np.uint16))
        s, _ = video.split_luma_chroma(l32, c)
        worst = np.abs(s.astype(np.int64) - share).max()
        assert 65535 / 510 - 1 <= worst <= 65535 / 510 + 0.5


class TestVideoErrors:
    def test_rejects_overbright_pixel(self):
        f = np.zeros((20350, 2), np.uint16)
        f[777] = [40000, 30000]
        with pytest.raises(ValueError, match="pixel 777: drive sum 70000"):
            video.encode_frame(f, seq=0)

    @pytest.mark.parametrize("bad", [np.zeros((20350, 2), np.uint8), np.zeros((20349, 2), np.uint16), [[0, 0]]])
    def test_rejects_wrong_shape_or_dtype(self, bad):
        with pytest.raises(ValueError, match=r"\(20350, 2\) uint16"):
            video.encode_frame(bad, seq=0)

    def test_rejects_sequence_out_of_range(self):
        with pytest.raises(FieldRangeError, match="0..127"):
            video.encode_frame(np.zeros((20350, 2), np.uint16), seq=128)

    def test_parse_errors_are_typed(self):
        good = video.encode_frame(np.zeros((20350, 2), np.uint16), seq=1)[0].tobytes()
        with pytest.raises(LengthError, match="1112 bytes"):
            video.parse_video(good[:-1])
        with pytest.raises(PanelError, match="panel 55"):
            video.parse_video(bytes([55]) + good[1:])
        with pytest.raises(UnknownTypeError):
            video.parse_video(bytes([0xC0]) + good[1:])


class TestControlGolden:
    def test_system_messages(self):
        assert control.encode_latch(5) == bytes.fromhex("7f 01 01 05")
        assert control.encode_status_request(7) == bytes.fromhex("7f 01 05 07")
        assert control.encode_hello(7) == bytes.fromhex("7f 01 06 07")
        assert control.decode_system(bytes.fromhex("7f 01 01 05")) == (control.OP_LATCH, 5)

    def test_system_errors(self):
        with pytest.raises(VersionError, match="version 2"):
            control.decode_system(bytes.fromhex("7f 02 01 05"))
        with pytest.raises(FieldRangeError, match="latch sequence 128"):
            control.decode_system(bytes.fromhex("7f 01 01 80"))
        with pytest.raises(PanelError):
            control.decode_system(bytes.fromhex("42 01 01 05"))
        with pytest.raises(LengthError):
            control.decode_system(bytes.fromhex("7f 01 01 05 00"))
        with pytest.raises(LengthError):
            control.decode_system(bytes.fromhex("7f 01"))
        with pytest.raises(UnknownTypeError):
            control.decode_system(bytes.fromhex("7f 01 09 00"))

    def test_polariser_one_panel(self):
        a = np.zeros(9)
        a[1:4] = [np.pi / 4, np.pi / 2, 3 * np.pi / 4]
        b = polariser.encode_polarisers(a, panel=2)
        assert b == bytes.fromhex("42 01 02 00 0000 4000 8000 c000" + "0000" * 5)
        msg = polariser.decode_polarisers(b)
        assert msg.address == 2 and msg.codes.tolist() == [[0, 0x4000, 0x8000, 0xC000, 0, 0, 0, 0, 0]]

    def test_polariser_whole_dome_round_trip(self):
        rng = np.random.default_rng(2)
        a = rng.uniform(0, np.pi, (55, 9))
        b = polariser.encode_polarisers(a)
        assert len(b) == 994 and b[:4] == bytes.fromhex("7f 01 02 00")
        back = polariser.codes_to_angles(polariser.decode_polarisers(b).codes)
        d = np.angle(np.exp(2j * (back - a))) / 2  # difference modulo pi
        assert np.abs(d).max() <= np.pi / 65536 / 2 + 1e-12

    @pytest.mark.parametrize("angle", [-0.1, np.pi, np.nan, np.inf])
    def test_polariser_rejects_bad_angle(self, angle):
        a = np.zeros((55, 9))
        a[3, 4] = angle
        with pytest.raises(ValueError, match=r"\(3, 4\).*allowed \[0, pi\)"):
            polariser.encode_polarisers(a)

    def test_dot_correction_and_brightness(self):
        dot = np.full(740, 100)
        dot[0], dot[739] = 50, 0
        b = config.encode_dot_correction(2, dot)
        assert len(b) == 744 and b[:8] == bytes.fromhex("42 01 03 00 32 64 64 64") and b[-1] == 0
        msg = config.decode_config(b)
        assert (msg.opcode, msg.address) == (config.OP_DOT_CORRECTION, 2) and msg.percent.tolist() == dot.tolist()
        assert config.encode_brightness(50) == bytes.fromhex("7f 01 04 00 32")
        assert config.decode_config(bytes.fromhex("7f 01 04 00 32")).percent.tolist() == [50]

    def test_config_errors(self):
        with pytest.raises(ValueError, match="entry 5 is 101"):
            config.encode_dot_correction(0, np.r_[np.full(5, 100), 101, np.zeros(734)])
        with pytest.raises(FieldRangeError, match="is 101"):
            config.decode_config(bytes.fromhex("7f 01 04 00 65"))
        with pytest.raises(PanelError):
            config.decode_config(bytes.fromhex("42 01 04 00 32"))
        with pytest.raises(PanelError):
            config.decode_config(bytes.fromhex("77 01 03 00") + bytes(740))
        with pytest.raises(LengthError):
            config.decode_config(bytes.fromhex("42 01 03 00") + bytes(739))


class TestReplies:
    def test_version_golden(self):
        b = replies.encode_version(7, 0x3F)
        assert b == bytes.fromhex("bf 01 81 07 01 01 00 37 0172 003f")
        r = replies.decode_reply(b)
        assert r.tag == 7 and r.fields["n_panels"] == 55 and "polarisers" in r.fields["capability_names"]

    def test_counters_round_trip(self):
        values = {n: i * 1000 + 1 for i, n in enumerate(replies.COUNTER_NAMES)}
        b = replies.encode_counters(3, values)
        assert b[:4] == bytes.fromhex("bf 01 82 03") and b[4:8] == bytes.fromhex("00 00 00 01")
        assert replies.decode_reply(b).fields == values

    def test_temperatures_faults_actuators(self):
        t = np.linspace(20, 70, 55)
        r = replies.decode_reply(replies.encode_temperatures(1, t, np.full(55, 8.81)))
        assert np.allclose(r.fields["temperature_c"], t, atol=0.005) and r.fields["current_a"][0] == 8.81
        faults = [(3, 120, "open"), (54, 739, "short")]
        b = replies.encode_faults(1, faults)
        assert b[4:] == bytes.fromhex("0002 03 0078 01 36 02e3 02")
        assert replies.decode_reply(b).fields["faults"][1] == {"panel": 54, "led": 739, "kind": "short"}
        codes = np.arange(495, dtype=np.uint16).reshape(55, 9)
        hold = np.zeros((55, 9), bool)
        hold[0, 0] = hold[54, 8] = True
        f = replies.decode_reply(replies.encode_actuators(1, codes, hold)).fields
        assert f["angle_codes"] == codes.tolist() and f["holding"] == hold.tolist()

    def test_reply_sizes_match_the_spec(self):
        z = np.zeros((55, 9))
        assert len(replies.encode_counters(0, {})) == 84
        assert len(replies.encode_temperatures(0, np.zeros(55), np.zeros(55))) == 224
        assert len(replies.encode_actuators(0, z.astype(np.uint16), z.astype(bool))) == 1056
        assert len(replies.encode_faults(0, [])) == 6

    def test_many_faults_are_counted_but_listed_up_to_360(self):
        faults = [(p, k, "open") for p in range(2) for k in range(300)]
        b = replies.encode_faults(0, faults)
        assert len(b) <= 1472  # fits one Ethernet frame
        f = replies.decode_reply(b).fields
        assert f["total"] == 600 and len(f["faults"]) == 360

    def test_reply_errors(self):
        with pytest.raises(UnknownTypeError):
            replies.decode_reply(bytes.fromhex("bf 01 99 00"))
        with pytest.raises(LengthError):
            replies.decode_reply(bytes.fromhex("bf 01 81 07 01"))
        with pytest.raises(FieldRangeError):
            replies.decode_reply(bytes.fromhex("bf 01 84 00 0001 37 0000 01"))
        with pytest.raises(ProtocolError):
            replies.decode_reply(bytes.fromhex("7f 01 81 07"))


def test_sequence_arithmetic():
    assert seq_newer(1, 0) and seq_newer(0, 127) and seq_newer(63, 0)
    assert not seq_newer(64, 0) and not seq_newer(0, 0) and not seq_newer(127, 0)
