"""Tracking-mode search (``tofpose.tracking``), all windows in one call: threshold each
window, label its 8-connected components, take the one of plausible size nearest the
prediction, and measure it."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit
from tofpose.kernels.camera import project

#: outcome codes of ``search_windows``
FOUND, NOT_FOUND, NO_SIZE, AT_EDGE = 0, 1, 2, 3


@jit
def _label_window(mask):
    """8-connected component labels (ph, pw) int32 of a bool mask, numbered 1.. in the
    raster order of each component's first pixel, with per-label area and coordinate
    sums (for the unweighted centroid). Returns labels, n, area, sum_u, sum_v."""
    ph, pw = mask.shape
    labels = np.zeros((ph, pw), np.int32)
    n_set = 0
    for r in range(ph):
        for c in range(pw):
            n_set += mask[r, c]
    area = np.zeros(n_set + 1, np.int64)  # at most one component per set pixel
    su = np.zeros(n_set + 1)
    sv = np.zeros(n_set + 1)
    stack_r = np.empty(n_set, np.int64)
    stack_c = np.empty(n_set, np.int64)
    n = 0
    for r0 in range(ph):
        for c0 in range(pw):
            if not mask[r0, c0] or labels[r0, c0]:
                continue
            n += 1
            labels[r0, c0] = n
            top = 0
            stack_r[top], stack_c[top] = r0, c0
            top += 1
            while top:
                top -= 1
                r, c = stack_r[top], stack_c[top]
                area[n] += 1
                su[n] += c
                sv[n] += r
                for dr in range(-1, 2):
                    for dc in range(-1, 2):
                        rr, cc = r + dr, c + dc
                        if 0 <= rr < ph and 0 <= cc < pw and mask[rr, cc] and not labels[rr, cc]:
                            labels[rr, cc] = n
                            stack_r[top], stack_c[top] = rr, cc
                            top += 1
    return labels, n, area, su, sv


@jit
def search_windows(gray, bounds, centres, diameters, threshold, background):
    """Find each window's reflector.

    gray : (H, W) float32; bounds : (n, 4) int64 windows [u0, u1) x [v0, v1) as
    (u0, u1, v0, v1); centres : (n, 2) predicted centres px; diameters : (n,) predicted
    diameters px; threshold : counts (the last acquisition's I_t); background : counts.

    A window's component is the one nearest the prediction (unweighted centroid) whose
    area is between max(1, a / 4) and max(4, 4 a), a the predicted disc's area; it must
    not touch the window's edge. Returns status (n,) int64 (``FOUND``, ``NOT_FOUND``,
    ``NO_SIZE``, ``AT_EDGE``), bbox (n, 4) int64 global (x, y, w, h), peak (n,) counts,
    centroid (n, 2) background-subtracted intensity-weighted (Eq. 19), starts (n + 1,)
    and flat: window j's pixels (flat indices, raster order) are
    ``flat[starts[j]:starts[j + 1]]``.
    """
    w_img = gray.shape[1]
    n = bounds.shape[0]
    status = np.full(n, NOT_FOUND, np.int64)
    bbox = np.zeros((n, 4), np.int64)
    peak = np.zeros(n)
    centroid = np.full((n, 2), np.nan)
    starts = np.zeros(n + 1, np.int64)
    pieces = []
    for j in range(n):
        u0, u1, v0, v1 = bounds[j, 0], bounds[j, 1], bounds[j, 2], bounds[j, 3]
        ph, pw = v1 - v0, u1 - u0
        mask = np.empty((ph, pw), np.bool_)
        for r in range(ph):
            for c in range(pw):
                mask[r, c] = gray[r + v0, c + u0] >= threshold
        labels, n_lab, area, su, sv = _label_window(mask)
        pieces.append(np.empty(0, np.int64))
        if n_lab == 0:
            continue
        expected = np.pi * (0.5 * diameters[j]) ** 2
        cu, cv = centres[j, 0] - u0, centres[j, 1] - v0
        best, best_d = 0, np.inf
        for k in range(1, n_lab + 1):
            if not max(1.0, 0.25 * expected) <= area[k] <= max(4.0, 4.0 * expected):
                continue
            d = np.hypot(su[k] / area[k] - cu, sv[k] / area[k] - cv)
            if d < best_d:
                best, best_d = k, d
        if best == 0:
            status[j] = NO_SIZE
            continue
        x0, y0, x1, y1 = pw, ph, -1, -1
        for r in range(ph):
            for c in range(pw):
                if labels[r, c] == best:
                    x0, x1 = min(x0, c), max(x1, c)
                    y0, y1 = min(y0, r), max(y1, r)
        if x0 == 0 or y0 == 0 or x1 + 1 >= pw or y1 + 1 >= ph:
            status[j] = AT_EDGE
            continue
        px = np.empty(area[best], np.int64)
        sw, swu, swv, top = 0.0, 0.0, 0.0, -np.inf
        i = 0
        for r in range(y0, y1 + 1):
            for c in range(x0, x1 + 1):
                if labels[r, c] == best:
                    val = np.float64(gray[r + v0, c + u0])
                    wt = max(val - background, 1e-9)
                    sw += wt
                    swu += wt * (c + u0)
                    swv += wt * (r + v0)
                    top = max(top, val)
                    px[i] = (r + v0) * w_img + c + u0
                    i += 1
        status[j] = FOUND
        bbox[j, 0], bbox[j, 1] = x0 + u0, y0 + v0
        bbox[j, 2], bbox[j, 3] = x1 - x0 + 1, y1 - y0 + 1
        peak[j] = top
        centroid[j, 0], centroid[j, 1] = swu / sw, swv / sw
        pieces[j] = px
    for j in range(n):
        starts[j + 1] = starts[j] + pieces[j].shape[0]
    flat = np.empty(starts[n], np.int64)
    for j in range(n):
        flat[starts[j] : starts[j + 1]] = pieces[j]
    return status, bbox, peak, centroid, starts, flat


@jit
def any_shared(flat, starts):
    """Do two windows' pixel lists (flat indices, each sorted) share a pixel?"""
    n = starts.shape[0] - 1
    for a in range(n):
        for b in range(a + 1, n):
            i, j = starts[a], starts[b]
            while i < starts[a + 1] and j < starts[b + 1]:
                if flat[i] == flat[j]:
                    return True
                if flat[i] < flat[j]:
                    i += 1
                else:
                    j += 1
    return False


@jit
def camera_windows(xyz, diameters_mm, R, t, fx, fy, cx, cy, dist, margin_px,
                   min_diameter_px, width, height):  # fmt: skip
    """``tracking.predict_windows`` as arrays (dist (5,): the lens distortion): the
    catalog indices (m,) of the reflectors to track, their window bounds (m, 4) int64
    (u0, u1, v0, v1), predicted centres (m, 2) px and diameters (m,) px. No windows when
    a reflector would be behind the camera."""
    n = xyz.shape[0]
    centres = xyz @ R.T + t
    d_px = np.empty(n)
    for i in range(n):
        if centres[i, 2] <= 0:
            return (np.empty(0, np.int64), np.empty((0, 4), np.int64), np.empty((0, 2)),
                    np.empty(0))  # fmt: skip
        d_px[i] = fx * diameters_mm[i] / centres[i, 2]
    uv = project(centres, fx, fy, cx, cy, dist)
    use = np.zeros(n, np.bool_)
    bounds = np.empty((n, 4), np.int64)
    for i in range(n):
        gap = np.inf
        for j in range(n):
            if j != i:
                du, dv = uv[i, 0] - uv[j, 0], uv[i, 1] - uv[j, 1]
                gap = min(gap, np.sqrt(du * du + dv * dv) - 0.5 * (d_px[i] + d_px[j]))
        half = 0.5 * d_px[i] + margin_px
        u0, u1 = int(np.floor(uv[i, 0] - half)), int(np.ceil(uv[i, 0] + half)) + 1
        v0, v1 = int(np.floor(uv[i, 1] - half)), int(np.ceil(uv[i, 1] + half)) + 1
        bounds[i, 0], bounds[i, 1], bounds[i, 2], bounds[i, 3] = u0, u1, v0, v1
        use[i] = (d_px[i] >= min_diameter_px and gap >= 2.0 and u0 >= 0 and v0 >= 0
                  and u1 <= width and v1 <= height)  # fmt: skip
    idx = np.flatnonzero(use)
    return idx, bounds[idx], uv[idx], d_px[idx]
