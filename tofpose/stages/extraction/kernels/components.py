"""Connected components of the active pixel set (§3.1.2-§3.2), from its runs.

The threshold pass records the active set's horizontal runs (``levels.threshold_mask``);
``run_labels`` joins them into 8-connected components numbered exactly as
``cv2.connectedComponents`` numbers them (tests hold it to OpenCV on random sets and
frames), at a few operations per run instead of a visit of every pixel of the set's
bounding box (OpenCV's labelling) and a second one to read its label image back into a
table. ``component_table`` gives what the blob criteria read: each
component's area, bounding box, brightest pixel, member pixels (flat indices, raster
order) and runs; ``component_median_ranges`` the median of its valid ranges.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.stats import median_inplace


class ComponentTable(NamedTuple):
    """Per component k = 0 .. K - 1 of a set given as its runs (``component_table``; 0,
    the background, left empty): ``area`` (K,) int64; ``bbox`` (K, 4) int64 (x, y, w, h);
    ``peak`` (K,) float32 counts; ``starts`` (K + 1,) and ``flat`` (P,) int64: the flat
    indices (row * W + col) of component k's pixels, in raster order, are
    ``flat[starts[k]:starts[k + 1]]``; ``run_order`` (R,) and ``run_starts`` (K + 1,)
    int64: its runs, in raster order, are ``run_order[run_starts[k]:run_starts[k + 1]]``
    (indices into the runs)."""

    area: np.ndarray
    bbox: np.ndarray
    peak: np.ndarray
    starts: np.ndarray
    flat: np.ndarray
    run_order: np.ndarray
    run_starts: np.ndarray


@jit
def _root(parent, i):
    """Root of run i in the union-find forest (path halving)."""
    while parent[i] != i:
        parent[i] = parent[parent[i]]
        i = parent[i]
    return i


@jit
def run_labels(runs):
    """The 8-connected components of a pixel set given as its horizontal runs (R, 3)
    (row, first column, last column + 1) in raster order (``levels.threshold_mask``),
    numbered as ``cv2.connectedComponents`` numbers them: labels (R,) int64, 1..K-1
    per run, and K (the background counts as label 0).

    Runs in adjacent rows whose columns overlap or touch diagonally are joined
    (union-find, each root the earliest run): a few operations per run instead of a
    visit of every pixel of the set's box. OpenCV scans the image in 2 x 2 blocks and
    numbers a component by its first block in that scan (the four pixels of a block
    are neighbours, so a block belongs to one component): components are sorted by the
    block row and then the block column of their first pixel in block order."""
    n = runs.shape[0]
    parent = np.arange(n)
    prev_a, prev_b = 0, 0  # the previous row's runs are [prev_a, prev_b)
    i = 0
    while i < n:
        r = runs[i, 0]
        j = i
        while j < n and runs[j, 0] == r:
            j += 1
        if prev_b == prev_a or runs[prev_a, 0] != r - 1:
            prev_a, prev_b = i, i  # no run in the row above
        first = prev_a
        for q in range(i, j):
            for p in range(first, prev_b):
                if runs[p, 2] < runs[q, 1]:  # p ends left of q's reach: so for later q
                    first = p + 1
                    continue
                if runs[p, 1] > runs[q, 2]:  # p starts right of q's reach
                    break
                a, b = _root(parent, p), _root(parent, q)
                if a < b:
                    parent[b] = a
                elif b < a:
                    parent[a] = b
        prev_a, prev_b = i, j
        i = j
    big = np.iinfo(np.int64).max
    block_row = np.full(n, big, np.int64)
    block_col = np.full(n, big, np.int64)
    root = np.empty(n, np.int64)
    for q in range(n):
        rt = _root(parent, q)
        root[q] = rt
        br, bc = runs[q, 0] >> 1, runs[q, 1] >> 1
        if br < block_row[rt] or (br == block_row[rt] and bc < block_col[rt]):
            block_row[rt], block_col[rt] = br, bc
    roots = np.flatnonzero(root == np.arange(n))
    key = np.empty(roots.shape[0], np.int64)
    for a in range(roots.shape[0]):
        key[a] = block_row[roots[a]] * (1 << 31) + block_col[roots[a]]
    order = np.argsort(key)
    label_of_root = np.zeros(n, np.int64)
    for a in range(roots.shape[0]):
        label_of_root[roots[order[a]]] = a + 1
    labels = np.empty(n, np.int64)
    for q in range(n):
        labels[q] = label_of_root[root[q]]
    return labels, roots.shape[0] + 1


@jit
def component_table(runs, labels, n_labels, gray):
    """Per component k = 0 .. n_labels - 1 (0, the background, is left empty) of a set
    given as its runs (R, 3) in raster order and their ``run_labels``; gray : (H, W)
    float32. Returns its ``ComponentTable``."""
    h_img, w_img = gray.shape
    area = np.zeros(n_labels, np.int64)
    x0 = np.full(n_labels, w_img, np.int64)  # (the background's box: as OpenCV's)
    y0 = np.full(n_labels, h_img, np.int64)
    x1 = np.full(n_labels, -1, np.int64)
    y1 = np.full(n_labels, -1, np.int64)
    peak = np.full(n_labels, -np.inf, np.float32)
    n_runs = runs.shape[0]
    run_starts = np.zeros(n_labels + 1, np.int64)
    for i in range(n_runs):
        r, first, end = runs[i, 0], runs[i, 1], runs[i, 2]
        k = labels[i]
        run_starts[k + 1] += 1
        area[k] += end - first
        x0[k] = min(x0[k], first)
        x1[k] = max(x1[k], end - 1)
        y0[k] = min(y0[k], r)
        y1[k] = max(y1[k], r)
        row = gray[r]
        top = peak[k]
        for c in range(first, end):
            top = max(top, row[c])
        peak[k] = top
    starts = np.zeros(n_labels + 1, np.int64)
    for k in range(1, n_labels):
        starts[k + 1] = starts[k] + area[k]
        run_starts[k + 1] += run_starts[k]
    fill = starts[:-1].copy()
    run_fill = run_starts[:-1].copy()
    flat = np.empty(starts[n_labels], np.int64)
    run_order = np.empty(n_runs, np.int64)
    for i in range(n_runs):
        k = labels[i]
        run_order[run_fill[k]] = i
        run_fill[k] += 1
        base = runs[i, 0] * w_img
        f = fill[k]
        for c in range(runs[i, 1], runs[i, 2]):
            flat[f] = base + c
            f += 1
        fill[k] = f
    bbox = np.empty((n_labels, 4), np.int64)
    for k in range(n_labels):
        bbox[k, 0] = x0[k]
        bbox[k, 1] = y0[k]
        bbox[k, 2] = x1[k] - x0[k] + 1
        bbox[k, 3] = y1[k] - y0[k] + 1
    return ComponentTable(
        area=area,
        bbox=bbox,
        peak=peak,
        starts=starts,
        flat=flat,
        run_order=run_order,
        run_starts=run_starts,
    )


@jit
def median_of_finite(values):
    """``np.median`` of the finite entries of a 1-D float32 array (NaN when none), with
    NumPy's arithmetic: the two middle values of an even count averaged in float32."""
    buf = np.empty(values.shape[0], values.dtype)
    n = 0
    for i in range(values.shape[0]):
        v = values[i]
        if np.isfinite(v):
            buf[n] = v
            n += 1
    if n == 0:
        return np.nan
    return median_inplace(buf[:n])


@jit
def component_median_ranges(flat, starts, distance_flat, which):
    """Median range (mm) of each listed component's valid pixels (NaN when it has none).

    flat, starts : from ``component_table``; distance_flat : (H * W,) float32 mm, NaN
    where invalid; which : (n,) int64 component labels. Returns (n,) float64.
    """
    out = np.empty(which.shape[0])
    for j in range(which.shape[0]):
        k = which[j]
        idx = flat[starts[k] : starts[k + 1]]
        out[j] = median_of_finite(distance_flat[idx])
    return out


@jit
def weighted_moments(us, vs, w):
    """Weighted centroid (Eq. 19) and eccentricity from the second moments of a point
    set: us, vs, w (n,) float64. Returns (u, v, eccentricity)."""
    sw = 0.0
    su = 0.0
    sv = 0.0
    for i in range(us.shape[0]):
        sw += w[i]
        su += us[i] * w[i]
        sv += vs[i] * w[i]
    cu, cv = su / sw, sv / sw
    cuu = 0.0
    cvv = 0.0
    cuv = 0.0
    for i in range(us.shape[0]):
        du, dv = us[i] - cu, vs[i] - cv
        cuu += w[i] * du * du
        cvv += w[i] * dv * dv
        cuv += w[i] * du * dv
    cuu, cvv, cuv = cuu / sw, cvv / sw, cuv / sw
    tr, det = cuu + cvv, cuu * cvv - cuv * cuv
    disc = np.sqrt(max(tr * tr / 4 - det, 0.0))
    l1, l2 = tr / 2 + disc, tr / 2 - disc
    ecc = np.sqrt(max(0.0, 1.0 - l2 / l1)) if l1 > 1e-12 else 0.0
    return cu, cv, ecc
