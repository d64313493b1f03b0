"""The USB report and control-request formats: golden bytes, round trips, typed errors."""

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.locomotion.trackball import protocol as P

GOLDEN = P.Report(seq=0x01020304, t_us=0x1122334455, counts=(1, -1, 300, -70000), squal=(0x80, 0x20),
                  overflow=(False, True))
GOLDEN_BYTES = bytes.fromhex(
    "54" "02" "80" "20"          # id 'T', flags (sensor 1 overflow), squal0, squal1
    "04030201"                   # seq
    "5544332211000000"           # t_us
    "01000000" "ffffffff" "2c010000" "90eefeff"  # dx0 dy0 dx1 dy1
)


def test_golden_report_bytes():
    assert P.REPORT_SIZE == 32
    assert P.encode_report(GOLDEN) == GOLDEN_BYTES
    assert P.decode_report(GOLDEN_BYTES) == GOLDEN


def test_golden_info_bytes():
    info = P.Info(1, 2, 1000, 1200, True)
    assert P.encode_info(info) == bytes.fromhex("0102" "e803" "b004" "01" "00")
    assert P.decode_info(P.encode_info(info)) == info


i32 = st.integers(-(2**31), 2**31 - 1)


@settings(max_examples=500, deadline=None)
@given(seq=st.integers(0, 2**32 - 1), t=st.integers(0, 2**64 - 1), c=st.tuples(i32, i32, i32, i32),
       q=st.tuples(st.integers(0, 255), st.integers(0, 255)), o=st.tuples(st.booleans(), st.booleans()))
def test_round_trip(seq, t, c, q, o):
    r = P.Report(seq, t, c, q, o)
    assert P.decode_report(P.encode_report(r)) == r


@pytest.mark.parametrize("n", [0, 1, 7, 31, 33, 64])
def test_wrong_length_is_a_short_report(n):
    with pytest.raises(P.ShortReportError, match="32 bytes"):
        P.decode_report(bytes(n))


def test_wrong_id_and_unknown_flags_are_bad_reports():
    with pytest.raises(P.BadReportError, match="id"):
        P.decode_report(b"\x00" + GOLDEN_BYTES[1:])
    with pytest.raises(P.BadReportError, match="flags"):
        P.decode_report(GOLDEN_BYTES[:1] + b"\x80" + GOLDEN_BYTES[2:])
    assert issubclass(P.BadReportError, ValueError) and issubclass(P.ShortReportError, P.ReportError)


def test_counts_do_not_clip_at_one_metre_per_second():
    # PMW3360 at its highest resolution, 12000 cpi = 472 counts/mm; at 1 m/s even a whole second in one report fits
    counts = round(1000 * 12000 / 25.4)
    assert counts < 2**31 - 1


def test_sequence_gaps_wrap_around():
    assert P.seq_gap(None, 5) == 0
    assert P.seq_gap(4, 5) == 0
    assert P.seq_gap(4, 8) == 3
    assert P.seq_gap(2**32 - 1, 0) == 0
    assert P.seq_gap(2**32 - 2, 1) == 2
