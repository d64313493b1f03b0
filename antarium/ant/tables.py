"""Index tables of the compiled kernels in the narrowest integer type that holds them.

A decision reads every table of the eye, the KCs and the optic flow once, and together they are larger than a
core's L2 cache: narrow tables keep that traffic small (on the 2-core Intel VM of 2026-11-28 the difference was
within the timing noise; the results are the same whatever the width).
"""

from __future__ import annotations

import numpy as np


def index_table(indices, n: int) -> np.ndarray:
    """`indices` (any shape) into an array of `n` items, C-contiguous int16 when n <= 32,767, else int32."""
    return np.ascontiguousarray(indices, dtype=np.int16 if n <= np.iinfo(np.int16).max else np.int32)
