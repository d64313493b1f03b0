"""One reading of "a number" for every input check (`antarium.core.numbers`)."""

import math

import numpy as np
import pytest

from antarium.core.numbers import as_real, check_number


@pytest.mark.parametrize("value, expected", [(3, 3.0), (-2.5, -2.5), (np.float32(0.5), 0.5), (np.int64(7), 7.0),
                                             (10**400, math.inf), (-(10**400), -math.inf)])
def test_real_numbers_are_read_as_floats(value, expected):
    assert as_real(value) == expected
    assert type(as_real(value)) is float


@pytest.mark.parametrize("value", [True, False, np.bool_(True), "1", None, [1], 1j, b"1"])
def test_what_is_not_a_real_number_reads_as_nan(value):
    assert math.isnan(as_real(value))


def test_check_number_keeps_the_range_and_names_what_is_allowed():
    assert check_number("gain", 2, 0, 10) == 2.0
    assert check_number("count", np.int32(4), 1, integer=True) == 4
    with pytest.raises(ValueError, match=r"gain must be a finite number >= 0 and <= 10, got 11"):
        check_number("gain", 11, 0, 10)
    with pytest.raises(ValueError, match=r"count must be an integer >= 1, got 2.0"):
        check_number("count", 2.0, 1, integer=True)
    for bad in (math.nan, math.inf, True, "3", 10**400):
        with pytest.raises(ValueError, match="must be a finite number"):
            check_number("rate", bad)
