"""The temporal median of distance over the persistence history (§3.4, D-bar)."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


@jit
def column_medians(stack):
    """Median over frames of each pixel's distance, ignoring NaNs (NaN when a pixel has
    no valid frame): ``np.nanmedian(stack, axis=0)`` with NumPy's float32 arithmetic
    (an even count averages its two middle values in float32).

    stack : (K, P) float32, K frames of the same P pixels. Returns (P,) float32.
    """
    k_frames, n = stack.shape
    out = np.empty(n, np.float32)
    buf = np.empty(k_frames, np.float32)
    for p in range(n):
        m = 0
        for f in range(k_frames):
            v = stack[f, p]
            if np.isfinite(v):
                # insertion sort of at most K values
                i = m
                while i > 0 and buf[i - 1] > v:
                    buf[i] = buf[i - 1]
                    i -= 1
                buf[i] = v
                m += 1
        if m == 0:
            out[p] = np.nan
        elif m & 1:
            out[p] = buf[m >> 1]
        else:
            out[p] = (buf[(m >> 1) - 1] + buf[m >> 1]) / np.float32(2.0)
    return out
