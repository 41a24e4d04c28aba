"""Small-array statistics for the per-blob loops of the pipeline.

``np.median`` and ``np.mean`` spend most of their time on argument handling when the
array holds a few to a few hundred values, and the pipeline calls them tens of times a
frame. ``median_1d`` is ``np.median`` of a 1-D array without NaNs, computed the same way
(``np.partition`` around the middle, the two middle values averaged for an even count),
so it returns the identical value in a fraction of the calls.
"""

from __future__ import annotations

import numpy as np


def median_1d(values: np.ndarray) -> float:
    """``float(np.median(values))`` for a non-empty 1-D array without NaNs, shape (n,).
    A few float64 values are sorted as a Python list (the same float64 arithmetic)."""
    n = values.shape[0]
    k = n >> 1
    if n <= 32 and values.dtype == np.float64:
        s = sorted(values.tolist())
        return s[k] if n & 1 else (s[k - 1] + s[k]) / 2.0
    if n & 1:
        return float(np.partition(values, k)[k])
    part = np.partition(values, (k - 1, k))
    return float((part[k - 1] + part[k]) / 2.0)
