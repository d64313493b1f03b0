"""FicTrac lines: golden parse, round trips, malformed lines, frame conversion to the dome frame."""

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from antarium.core.ball import pole_motion
from antarium.locomotion.fictrac.protocol import (
    N_FIELDS,
    FicTracFrame,
    FicTracParseError,
    format_line,
    lab_to_dome,
    parse_line,
    to_sample,
)

# a line as FicTrac v2.1 writes it to its socket (ball rolling backwards under a forward-walking animal)
GOLDEN = ("FT, 42, 0.001, 0.02, -0.003, 0.0105, 0.0011, 0.021, -0.0031, 0.5, 0.6, 0.7, 1.5, 1.6, 1.7, "
          "3.25, -1.5, 0.25, 0.125, 0.021, 4.5, -0.75, 1600000000123.5, 41, 10.0, 36000123.5\n")


def test_golden_line():
    f = parse_line(GOLDEN)
    assert f.frame == 42 and f.seq == 41 and isinstance(f.frame, int)
    assert (f.d_rot_lab_x, f.d_rot_lab_y, f.d_rot_lab_z) == (0.0011, 0.021, -0.0031)
    assert f.match_error == 0.0105 and f.pos_x == 3.25 and f.heading == 0.25
    assert (f.forward, f.side) == (4.5, -0.75)
    assert (f.timestamp_ms, f.dt_ms, f.time_of_day_ms) == (1600000000123.5, 10.0, 36000123.5)
    # a .dat log line is the same without the prefix; bytes work too
    assert parse_line(GOLDEN[4:]) == f == parse_line(GOLDEN.encode())


def test_conversion_to_the_dome_frame():
    f = parse_line(GOLDEN)
    s = to_sample(f, t=12.5)
    assert s.t == 12.5 and s.seq == 42 and s.t_device == pytest.approx(1600000000.1235)
    assert s.rotation == (0.0011, -0.021, 0.0031)  # +Y right -> +y left, +Z down -> +z up
    assert s.quality == 1.0
    assert to_sample(f, 0.0, max_match_error=0.021).quality == pytest.approx(0.5)
    assert to_sample(f, 0.0, max_match_error=0.001).quality == 0.0
    # FicTrac's ball turning about +Y (right) is an animal walking forward: forward motion on the top pole
    dx, dy, _ = pole_motion(s.rotation, 0.05)
    assert dx > 0 and abs(dy) < dx


def test_lab_to_dome_is_a_proper_rotation():
    # a half turn about x keeps handedness: cross products map to cross products
    a, b = (0.1, 0.2, 0.3), (-0.4, 0.5, 0.6)
    cross = lambda u, v: (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])  # noqa: E731
    assert lab_to_dome(*cross(a, b)) == pytest.approx(cross(lab_to_dome(*a), lab_to_dome(*b)))


finite = st.floats(-1e9, 1e9, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(frame=st.integers(0, 2**40), seq=st.integers(0, 2**40), values=st.lists(finite, min_size=23, max_size=23))
def test_round_trip(frame, seq, values):
    f = FicTracFrame(frame, *values[:21], seq, *values[21:])
    assert parse_line(format_line(f)) == f
    assert parse_line(format_line(f, prefix=False)) == f


# the same frame as FicTrac 2.0 wrote it to its log and TCP socket: 23 values, no prefix (its doc/data_header.txt)
GOLDEN_V20 = ("42, 0.001, 0.02, -0.003, 0.0105, 0.0011, 0.021, -0.0031, 0.5, 0.6, 0.7, 1.5, 1.6, 1.7, "
              "3.25, -1.5, 0.25, 0.125, 0.021, 4.5, -0.75, 1600000000123.5, 41\n")


def test_a_fictrac_2_0_line_reads_with_fields_24_and_25_nan():
    f = parse_line(GOLDEN_V20)
    assert f[:23] == parse_line(GOLDEN)[:23]
    assert math.isnan(f.dt_ms) and math.isnan(f.time_of_day_ms)
    assert to_sample(f, t=1.0) == to_sample(parse_line(GOLDEN), t=1.0)
    assert format_line(f, prefix=False) == GOLDEN_V20.strip()   # written back as 2.0 wrote it
    assert parse_line(format_line(f))[:23] == f[:23]


@pytest.mark.parametrize("line, match", [
    ("", "25 comma-separated values \\(23 from FicTrac 2.0\\), got 1"),
    (GOLDEN_V20.strip() + ", 10.0", "got 24"),
    ("FT, 1, 2, 3", "got 3"),
    (GOLDEN.replace("0.5,", "abc,"), "field 9 \\(rot_cam_x\\) is not a number: 'abc'"),
    (GOLDEN.replace("0.5,", "nan,"), "field 9 .* not finite"),
    (GOLDEN.replace("FT, 42,", "FT, 42.5,"), "field 1 \\(frame\\) must be an integer"),
    (GOLDEN.strip() + ", 7", "got 26"),
    (b"\xff\xfe", "not ASCII"),
])
def test_malformed_lines_raise_a_clear_error(line, match):
    with pytest.raises(FicTracParseError, match=match):
        parse_line(line)


def test_field_table_has_25_fields():
    assert len(FicTracFrame._fields) == N_FIELDS == 25
    assert math.isclose(parse_line(GOLDEN).direction, 0.125)
