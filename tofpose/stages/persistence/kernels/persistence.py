"""The temporal median of distance over the persistence history (§3.4, D-bar)."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.extraction.constants import MAD_TO_SIGMA
from tofpose.stages.persistence.constants import (
    RANGE_TEST_CLIP,
    RANGE_TEST_MAX_PIXELS,
    RANGE_TEST_MIN_PIXELS,
)


@jit
def _insertion_median(stack, p, buf):
    """The median over frames of pixel p of stack (K, P), ignoring NaNs (NaN when none),
    by insertion sort of the at most K valid values (buf : (K,) scratch)."""
    m = 0
    for f in range(stack.shape[0]):
        v = stack[f, p]
        if np.isfinite(v):
            i = m
            while i > 0 and buf[i - 1] > v:
                buf[i] = buf[i - 1]
                i -= 1
            buf[i] = v
            m += 1
    if m == 0:
        return np.float32(np.nan)
    if m & 1:
        return buf[m >> 1]
    return (buf[(m >> 1) - 1] + buf[m >> 1]) / np.float32(2.0)


@jit
def column_medians(stack):
    """Median over frames of each pixel's distance, ignoring NaNs (NaN when a pixel has
    no valid frame): ``np.nanmedian(stack, axis=0)`` with NumPy's float32 arithmetic
    (an even count averages its two middle values in float32).

    stack : (K, P) float32, K frames of the same P pixels. Returns (P,) float32.

    With five frames (a full persistence history) each pixel's values go through
    ``_median_of_five``."""
    k_frames, n = stack.shape
    out = np.empty(n, np.float32)
    buf = np.empty(k_frames, np.float32)
    if k_frames != 5:
        for p in range(n):
            out[p] = _insertion_median(stack, p, buf)
        return out
    for p in range(n):
        v0, v1, v2, v3, v4 = stack[0, p], stack[1, p], stack[2, p], stack[3, p], stack[4, p]
        if _finite5(v0, v1, v2, v3, v4):
            out[p] = _median_of_five(v0, v1, v2, v3, v4)
        else:
            out[p] = _insertion_median(stack, p, buf)
    return out


@jit
def _median_of_five(v0, v1, v2, v3, v4):
    """The median of five finite values: a sorting network of nine compare-exchanges
    (Knuth, TAOCP 5.3.4) on scalars, in registers (the compiler drops what the middle
    output does not depend on)."""
    v0, v1 = min(v0, v1), max(v0, v1)
    v3, v4 = min(v3, v4), max(v3, v4)
    v2, v4 = min(v2, v4), max(v2, v4)
    v2, v3 = min(v2, v3), max(v2, v3)
    v0, v3 = min(v0, v3), max(v0, v3)
    v0, v2 = min(v0, v2), max(v0, v2)
    v1, v4 = min(v1, v4), max(v1, v4)
    v1, v3 = min(v1, v3), max(v1, v3)
    return max(v1, v2)


@jit
def _finite5(v0, v1, v2, v3, v4):
    """Are the five values finite?"""
    return (
        np.isfinite(v0)
        and np.isfinite(v1)
        and np.isfinite(v2)
        and np.isfinite(v3)
        and np.isfinite(v4)
    )


@jit
def _median_with_nans(v0, v1, v2, v3, v4, column, buf):
    """The median of five float32 values of which some are not finite, ignoring them
    (NaN when none is): ``_insertion_median`` (column : (5, 1), buf : (5,) scratch)."""
    column[0, 0], column[1, 0], column[2, 0], column[3, 0], column[4, 0] = v0, v1, v2, v3, v4
    return _insertion_median(column, 0, buf)


@jit
def medians_and_counts_at(frames, masks, n_older, flat, out):
    """D-bar and the counter C of §3.4 where they are read, at the blobs' pixels ``flat``
    (P,) (flat indices): the median over the first ``1 + n_older`` of ``frames`` (a
    tuple of (H, W) float32, current frame first) ignoring NaNs, written into ``out``
    (H, W) float32 at each index (the rest of ``out`` is left as it was); and returned,
    the counts (P,) int64, 1 + the number of the first ``n_older`` ``masks`` (a tuple of
    (H * W,) bool) holding the pixel. The values of ``column_medians(gather_stack(...))``
    and ``pixel_counts(masks, n_older, flat, 1)``.

    With a full history of five frames each pixel's five values and four mask bits are
    read together and the values sorted in registers (``_median_of_five``), pixel
    by pixel: one pass over the history frames' blob pixels instead of a stack of five
    rows and four more passes over the masks."""
    o = out.reshape(-1)
    if n_older != 4:
        med = column_medians(gather_stack(frames, 1 + n_older, flat))
        for i in range(flat.shape[0]):
            o[flat[i]] = med[i]
        return pixel_counts(masks, n_older, flat, 1)
    # a runtime index: a tuple shorter than five (K < 5) must still compile
    k = n_older - 4
    f0, f1 = frames[k].reshape(-1), frames[k + 1].reshape(-1)
    f2, f3, f4 = frames[k + 2].reshape(-1), frames[k + 3].reshape(-1), frames[k + 4].reshape(-1)
    m0, m1, m2, m3 = masks[k], masks[k + 1], masks[k + 2], masks[k + 3]
    counts = np.empty(flat.shape[0], np.int64)
    column = np.empty((5, 1), np.float32)
    buf = np.empty(5, np.float32)
    for i in range(flat.shape[0]):
        p = flat[i]
        counts[i] = 1 + np.int64(m0[p]) + np.int64(m1[p]) + np.int64(m2[p]) + np.int64(m3[p])
        v0, v1, v2, v3, v4 = f0[p], f1[p], f2[p], f3[p], f4[p]
        if _finite5(v0, v1, v2, v3, v4):
            o[p] = _median_of_five(v0, v1, v2, v3, v4)
        else:
            o[p] = _median_with_nans(v0, v1, v2, v3, v4, column, buf)
    return counts


@jit
def consistent(current, previous, tol_px):
    """Do two centroid sets (n, 2), (m, 2) describe the same static scene? At least half
    of the current centroids (rounded up, at least one) have a previous one within
    max(4 tol, 2 px), and the median of those nearest distances is at most tol.

    A centroid that is NaN (a part split out of a merged component has no moment
    centroid before it is measured) has no neighbour and is nobody's neighbour: it
    counts in n but cannot be near, and a NaN previous centroid is skipped. (The NumPy
    version this replaced let one NaN previous centroid make every distance NaN, so a
    frame with a split 7+8 pair was always "moving" and persistence never combined
    frames at the ranges where the pair merges.)"""
    n, m = current.shape[0], previous.shape[0]
    if n == 0 or m == 0:
        return n == m
    near_d = np.empty(n)
    k = 0
    for i in range(n):
        best = np.inf
        for j in range(m):
            d = np.hypot(current[i, 0] - previous[j, 0], current[i, 1] - previous[j, 1])
            if d < best:  # False for NaN
                best = d
        if best < max(4 * tol_px, 2.0):
            near_d[k] = best
            k += 1
    if k < max(1, int(np.ceil(0.5 * n))):
        return False
    s = np.sort(near_d[:k])
    med = s[k >> 1] if k & 1 else (s[(k >> 1) - 1] + s[k >> 1]) / 2.0
    return med <= tol_px


@jit
def mean_in_boxes(gray, older, n_older, boxes, out):
    """I-bar (§3.4) where it is read: ``(gray + sum(older)) / n`` inside each box grown
    by 2 px, written into ``out``; the rest of ``out`` is left as it was (pass
    ``gray.copy()`` for this frame's gray elsewhere), in float32 as NumPy computes it.

    gray : (H, W) float32; older : tuple of (H, W) float32 frames, of which the first
    ``n_older`` are used (the tuple has a fixed length per configuration, so that one
    compiled version serves every history length); boxes : (b, 4) int64 (x, y, w, h);
    out : (H, W) float32. Returns ``out``."""
    h, w = gray.shape
    n = np.float32(1 + n_older)
    for j in range(boxes.shape[0]):
        x, y, bw, bh = boxes[j, 0], boxes[j, 1], boxes[j, 2], boxes[j, 3]
        r0, r1 = max(y - 2, 0), min(y + bh + 2, h)
        c0, c1 = max(x - 2, 0), min(x + bw + 2, w)
        # row by row, the older frames summed one frame at a time into a row buffer (the
        # same float32 additions in the same order as a per-pixel loop over the frames);
        # 1-D loops over contiguous rows, which the compiler vectorises (the 2-D loop
        # this replaced was not)
        s = np.empty(c1 - c0, np.float32)
        for r in range(r0, r1):
            s[:] = 0
            for i in range(n_older):
                row = older[i][r]
                for c in range(c1 - c0):
                    s[c] += row[c0 + c]
            g_row, out_row = gray[r], out[r]
            for c in range(c1 - c0):
                out_row[c0 + c] = (g_row[c0 + c] + s[c]) / n
    return out


@jit
def median_of_counts(hist, m):
    """``np.median`` of m small non-negative integers given as their histogram
    ``hist[v]`` = how many equal v (a counting median: linear, exact)."""
    q = m >> 1
    seen, lo, hi = 0, -1, -1
    for v in range(hist.shape[0]):
        seen += hist[v]
        if lo < 0 and seen > q - 1:
            lo = v
        if seen > q:
            hi = v
            break
    return float(hi) if m & 1 else (lo + hi) / 2.0


@jit
def pixel_mask(flat, size):
    """(size,) bool, True at the flat indices ``flat`` (P,): a frame's candidate-blob
    pixels as the history keeps them (NumPy's fancy assignment costs ~1 ns a pixel more
    than the loop)."""
    mask = np.zeros(size, np.bool_)
    for i in range(flat.shape[0]):
        mask[flat[i]] = True
    return mask


@jit
def pixel_counts(masks, n_masks, flat, base=0):
    """(P,) int64: at each flat index of ``flat``, ``base`` + the number of the first
    ``n_masks`` (H * W,) bool ``masks`` holding it."""
    counts = np.full(flat.shape[0], base, np.int64)
    for f in range(n_masks):  # one frame at a time (no tuple selection per pixel)
        mask = masks[f]
        for i in range(flat.shape[0]):
            counts[i] += mask[flat[i]]
    return counts


@jit
def blob_count_medians(counts, starts, n_values):
    """Per blob, the median of its pixels' counts (``counts[starts[j]:starts[j + 1]]``,
    integers in [0, n_values)). Returns (n,) float64."""
    n = starts.shape[0] - 1
    out = np.empty(n)
    hist = np.empty(n_values, np.int64)
    for j in range(n):
        hist[:] = 0
        for i in range(starts[j], starts[j + 1]):
            hist[counts[i]] += 1
        out[j] = median_of_counts(hist, starts[j + 1] - starts[j])
    return out


@jit
def counter_medians(masks, n_masks, flat, starts, base=0):
    """The counter image C of §3.4 read at each blob's pixels: per blob, the median over
    its pixels (flat indices ``flat[starts[j]:starts[j + 1]]``) of the number of frames,
    of the first ``n_masks`` (H * W,) bool masks given and ``base`` frames known to hold
    every blob pixel (the current one, when its mask is not among ``masks``), in which
    the pixel belonged to a candidate blob. Returns (n,) float64."""
    counts = pixel_counts(masks, n_masks, flat, base)
    return blob_count_medians(counts, starts, base + n_masks + 1)


@jit
def gather_stack(frames, n_frames, flat):
    """(K, P) float32: each of the first K = ``n_frames`` (H, W) frames read at the flat
    indices (P,)."""
    out = np.empty((n_frames, flat.shape[0]), np.float32)
    for f in range(n_frames):
        src = frames[f].reshape(-1)
        for i in range(flat.shape[0]):
            out[f, i] = src[flat[i]]
    return out


@jit
def ranges_consistent(current, previous, flat, starts, z):
    """Do two distance frames show the blobs at the same ranges, within their noise?
    The test the centroids' ``consistent`` cannot make: a target turning about an axis
    through itself changes its markers' ranges by millimetres a frame while their
    images hardly move, and combining such frames lags the ranges (D-bar).

    Per blob (pixels ``flat[starts[j]:starts[j + 1]]``, every k-th of them,
    k = P // ``RANGE_TEST_MAX_PIXELS``, so that fewer than twice that are read) with at
    least ``RANGE_TEST_MIN_PIXELS`` pixels valid in both frames: the pixel differences
    delta = current - previous, their median m and its standard error from their MAD
    (1.4826 MAD sqrt(pi / 2) / sqrt(n): the median of n Gaussian values); t = m / that.
    Consistent when the sum of t^2, each clipped at ``RANGE_TEST_CLIP``, is within
    chi^2 of the number of blobs tested at the standard normal quantile ``z``
    (Wilson-Hilferty), or when no blob can be tested. The clip is for the tails: a
    blob of 5-20 pixels with mixed pixels on its rim reads t^2 ~ 20 now and then on a
    static scene (a MAD of few values), so one blob alone never cuts the history;
    moving markers cut it together.

    current, previous : (H * W,) or (H, W) float32 mm, NaN where invalid."""
    cur = current.reshape(-1)
    prev = previous.reshape(-1)
    n_blobs = starts.shape[0] - 1
    stat, tested = 0.0, 0
    d = np.empty(2 * RANGE_TEST_MAX_PIXELS)  # a stride of (P // max) reads < 2 max
    for j in range(n_blobs):
        lo, hi = starts[j], starts[j + 1]
        step = max(1, (hi - lo) // RANGE_TEST_MAX_PIXELS)
        m = 0
        for i in range(lo, hi, step):
            a, b = cur[flat[i]], prev[flat[i]]
            if np.isfinite(a) and np.isfinite(b) and m < d.shape[0]:
                d[m] = np.float64(a) - np.float64(b)
                m += 1
        if m < RANGE_TEST_MIN_PIXELS:
            continue
        med = median_inplace(d[:m].copy())
        dev = np.abs(d[:m] - med)
        mad = median_inplace(dev)
        se = MAD_TO_SIGMA * mad * np.sqrt(0.5 * np.pi / m)
        if se <= 0.0:
            continue
        stat += min((med / se) ** 2, RANGE_TEST_CLIP)
        tested += 1
    if tested == 0:
        return True
    k = np.float64(tested)
    c = 2.0 / (9.0 * k)
    limit = k * (1.0 - c + z * np.sqrt(c)) ** 3
    return stat <= limit
