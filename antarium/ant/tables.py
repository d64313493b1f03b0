"""Index tables of the compiled kernels in the narrowest integer type that holds them.

A decision reads every table of the eye, the KCs and the optic flow once; together they are larger than a core's
L2 cache, so each stage reloads its tables from L3, and their size, not the arithmetic, sets the stage's time.
"""

from __future__ import annotations

import numpy as np


def index_table(indices, n: int) -> np.ndarray:
    """`indices` (any shape) into an array of `n` items, C-contiguous int16 when n <= 32,767, else int32."""
    return np.ascontiguousarray(indices, dtype=np.int16 if n <= np.iinfo(np.int16).max else np.int32)
