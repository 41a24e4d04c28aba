"""Medians with NumPy's arithmetic, for the kernels (``np.median`` averages the two middle
values of an even count in the array's own precision)."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


@jit
def median_inplace(v):
    """``float(np.median(v))`` of a 1-D float32 or float64 array without NaNs; reorders
    ``v`` (pass a copy to keep it)."""
    n = v.shape[0]
    k = n >> 1
    s = np.partition(v, k)
    if n & 1:
        return float(s[k])
    return float((s[:k].max() + s[k]) / v.dtype.type(2.0))
