"""Frame checks and frame levels (§3.1.1) in single passes over the image."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.extraction.constants import DARK_PERCENTILE


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
def checked_frame(gray, distance_mm):
    """``gray`` as float32 and ``clean_distance(distance_mm)`` in one pass over each row
    of both images (half the time of NumPy's conversion followed by the clean copy).
    gray : (H, W) integer counts; distance_mm : (H, W) float. Returns two (H, W) float32."""
    h, w = gray.shape
    g = np.empty((h, w), np.float32)
    d = np.empty((h, w), np.float32)
    nan = np.float32(np.nan)
    for r in range(h):
        g_in, g_out, d_in, d_out = gray[r], g[r], distance_mm[r], d[r]
        for c in range(w):
            g_out[c] = np.float32(g_in[c])
        for c in range(w):
            v = np.float32(d_in[c])
            d_out[c] = v if (v > 0) & (v < np.float32(np.inf)) else nan  # NaN > 0 is False
    return g, d


#: the counting median handles values v with 2 v an integer in [0, this)
_COUNTING_LIMIT = 1 << 17


@jit
def _kth_counted(counts, k):
    """Index of the k-th smallest (0-based) value in a histogram of counts."""
    seen = 0
    for i in range(counts.shape[0]):
        seen += counts[i]
        if seen > k:
            return i
    return counts.shape[0] - 1


@jit
def _median_counted(counts, n):
    """``np.median`` in float32 of the n values whose doubled values are histogrammed in
    ``counts`` (``_median_of_levels``' arithmetic)."""
    k = n >> 1
    hi = np.float32(_kth_counted(counts, k) / 2.0)
    if n & 1:
        return float(hi)
    lo = np.float32(_kth_counted(counts, k - 1) / 2.0)
    return float((lo + hi) / np.float32(2.0))


@jit
def _half_grid_counts(v):
    """Histogram of 2 v for float32 values (n,) that are all multiples of 0.5 in [0,
    65536) (gray counts, and their deviations from such a median), indexed by 2 v; an
    empty histogram when any value is not."""
    top = 0.0
    for i in range(v.shape[0]):
        d = v[i] * 2
        if not (d >= 0 and d < _COUNTING_LIMIT and d == np.floor(d)):
            return np.zeros(0, np.int64)
        top = max(top, d)
    counts = np.zeros(int(top) + 1, np.int64)
    for i in range(v.shape[0]):
        counts[int(v[i] * 2)] += 1
    return counts


@jit
def _median_of_levels(v):
    """``np.median`` of float32 values (n,); by counting when every value is a multiple
    of 0.5 in [0, 65536) (``_half_grid_counts``), which is linear in n and not slowed by
    the many ties of a dark background."""
    counts = _half_grid_counts(v)
    if counts.shape[0] == 0:
        return median_inplace(v.copy())
    return _median_counted(counts, v.shape[0])


@jit
def _level_and_spread(v, counts):
    """(median, median absolute deviation) of float32 values (n,), both as
    ``_median_of_levels`` gives them; counts : their ``_half_grid_counts``. When every
    value is a multiple of 0.5 in [0, 65536) and the median a multiple of 0.5 too, both
    come from that one histogram: the deviations' histogram is the values' folded at the
    median, and no second pass over the values is needed."""
    n = v.shape[0]
    if counts.shape[0] == 0:
        bg = median_inplace(v.copy())
    else:
        bg = _median_counted(counts, n)
        twice = np.float32(bg) * 2
        if twice == np.floor(twice):
            centre = int(twice)
            folded = np.zeros(max(centre, counts.shape[0] - 1 - centre) + 1, np.int64)
            for b in range(counts.shape[0]):
                folded[abs(b - centre)] += counts[b]
            return bg, _median_counted(folded, n)
    dev = np.empty(n, np.float32)
    bg32 = np.float32(bg)
    for i in range(n):
        dev[i] = abs(v[i] - bg32)
    return bg, _median_of_levels(dev)


@jit
def frame_level_stats(gray, stride, saturated_counts):
    """Background (median of a strided subsample), its median absolute deviation, the
    number of pixels at or above ``saturated_counts`` and the no-return level (the
    ``DARK_PERCENTILE``-th percentile of the subsample, nearest rank: the gray of pixels
    that see nothing within range, the zero of the amplitudes that
    ``mixed_pixels`` mixes). (The brightest pixel is NumPy's
    ``gray.max()``, several times faster than a compiled loop: numba does not vectorise a
    max reduction.)

    gray : (H, W) float32. Returns (background, mad, n_saturated, dark); background and
    mad with NumPy's float32 median arithmetic.
    """
    h, w = gray.shape
    sub = np.empty(((h + stride - 1) // stride) * ((w + stride - 1) // stride), np.float32)
    n = 0
    for r in range(0, h, stride):
        for c in range(0, w, stride):
            sub[n] = gray[r, c]
            n += 1
    counts = _half_grid_counts(sub[:n])  # one histogram for all three levels
    bg, mad = _level_and_spread(sub[:n], counts)
    k = int(n * DARK_PERCENTILE / 100.0)
    dark = _kth_counted(counts, k) / 2.0 if counts.shape[0] else float(np.sort(sub[:n])[k])
    sat = np.float32(saturated_counts)
    flat = gray.reshape(-1)
    n_sat = 0
    for i in range(flat.shape[0]):
        if flat[i] >= sat:
            n_sat += 1
    return bg, mad, n_sat, dark


@jit
def threshold_mask(gray, threshold):
    """The active pixel set ``gray >= threshold`` (§3.1.1) in one pass: uint8 mask
    (H, W), its runs, its size, and its bounding box as a tuple (x, y, w, h), as
    ``cv2.boundingRect`` gives it ((0, 0, 0, 0) when empty). gray : (H, W) float32.

    runs : (R, 3) int64, the set's maximal horizontal runs of pixels in raster order, as
    (row, first column, last column + 1): the labelled components are read run by run
    (``components.component_table``) instead of scanning every pixel of their box."""
    h, w = gray.shape
    mask = np.empty((h, w), np.uint8)
    runs = np.empty((h * ((w + 1) // 2), 3), np.int64)  # at most (w + 1) // 2 a row
    n_runs = 0
    n = 0
    x0, y0, x1, y1 = w, h, -1, -1
    t = np.float32(threshold)
    for r in range(h):
        row_n = 0
        for c in range(w):
            on = gray[r, c] >= t
            mask[r, c] = on
            row_n += on
        if row_n:
            n += row_n
            y0 = min(y0, r)
            y1 = r
            c = 0
            while c < w:
                if mask[r, c]:
                    first = c
                    while c < w and mask[r, c]:
                        c += 1
                    runs[n_runs, 0] = r
                    runs[n_runs, 1] = first
                    runs[n_runs, 2] = c
                    n_runs += 1
                    x0 = min(x0, first)
                    x1 = max(x1, c - 1)
                else:
                    c += 1
    if n == 0:
        return mask, runs[:0], 0, (0, 0, 0, 0)
    return mask, runs[:n_runs], n, (x0, y0, x1 - x0 + 1, y1 - y0 + 1)
