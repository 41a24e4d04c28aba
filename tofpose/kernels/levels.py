"""Frame checks and frame levels (§3.1.1) in single passes over the image."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


@jit
def clean_distance(distance_mm):
    """float32 copy of a distance image with non-finite and non-positive values set to
    NaN (invalid pixels). distance_mm : (H, W) float; returns (H, W) float32."""
    h, w = distance_mm.shape
    out = np.empty((h, w), np.float32)
    for r in range(h):
        for c in range(w):
            v = np.float32(distance_mm[r, c])
            out[r, c] = v if (np.isfinite(v) and v > 0) else np.nan
    return out


@jit
def _median32(v):
    n = v.shape[0]
    k = n >> 1
    s = np.partition(v, k)
    return float(s[k]) if n & 1 else float((s[:k].max() + s[k]) / np.float32(2.0))


@jit
def frame_level_stats(gray, stride, saturated_counts):
    """Background (median of a strided subsample), its median absolute deviation, the
    brightest pixel and the number of pixels at or above ``saturated_counts``.

    gray : (H, W) float32. Returns (background, mad, i_max, n_saturated); background and
    mad with NumPy's float32 median arithmetic.
    """
    h, w = gray.shape
    sub = np.empty(((h + stride - 1) // stride) * ((w + stride - 1) // stride), np.float32)
    n = 0
    for r in range(0, h, stride):
        for c in range(0, w, stride):
            sub[n] = gray[r, c]
            n += 1
    bg = _median32(sub[:n].copy())
    dev = np.empty(n, np.float32)
    bg32 = np.float32(bg)
    for i in range(n):
        dev[i] = abs(sub[i] - bg32)
    mad = _median32(dev)
    i_max = -np.inf
    n_sat = 0
    for r in range(h):
        for c in range(w):
            v = gray[r, c]
            i_max = max(i_max, v)
            if v >= saturated_counts:
                n_sat += 1
    return bg, mad, float(i_max), n_sat
