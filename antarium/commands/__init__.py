"""Sub-commands of the `antarium` command line (see `antarium.cli.COMMANDS`)."""

from __future__ import annotations

import argparse
import math


def require_seconds(args: argparse.Namespace, *names: str) -> None:
    """ValueError naming the first of the options `names` (attribute names of `args`) that is given but is not a
    finite number of seconds > 0; options left at None are not given."""
    for name in names:
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0):
            raise ValueError(f"--{name.replace('_', '-')} must be a positive number of seconds, got {value:g}")
