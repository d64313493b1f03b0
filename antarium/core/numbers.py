"""One reading of "a number" for every check of user input (commands, scenes, configs, specs, scripts):
Python's and numpy's real numbers count, booleans never do, and an integer too large for a float is infinite."""

from __future__ import annotations

import math
import numbers
from typing import Any


def as_real(value: Any) -> float:
    """`value` as a float when it is a real number (int, float, numpy integer or floating; not a bool), NaN for
    anything else (strings, None, booleans, complex), +-inf for an integer too large for a float."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):  # numpy's bool_ is not a Real
        return math.nan
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def check_number(name: str, value: Any, low: float = -math.inf, high: float = math.inf,
                 integer: bool = False) -> float | int:
    """`value` as a float (an int when `integer`) in [low, high]; a bool, a string, NaN or infinity raise one
    ValueError naming `name`, the value and what is allowed."""
    number = as_real(value)
    ok = math.isfinite(number) and (not integer or isinstance(value, numbers.Integral))
    if not (ok and low <= number <= high):
        what = "an integer" if integer else "a finite number"
        bounds = [f">= {low:g}"] * (low > -math.inf) + [f"<= {high:g}"] * (high < math.inf)
        raise ValueError(f"{name} must be {what}{' ' + ' and '.join(bounds) if bounds else ''}, "
                         f"got {repr(value)[:60]}")
    return int(value) if integer else number


def is_float_text(text: str) -> bool:
    """Whether `float(text)` reads a field of a text file ("nan" and "inf" do; check finiteness apart)."""
    try:
        float(text)
    except ValueError:
        return False
    return True
