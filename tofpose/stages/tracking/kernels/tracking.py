"""Tracking-mode search (``tofpose.stages.tracking.tracking``), all windows in one call: threshold
each
window, label its 8-connected components, take the one of plausible size nearest the
prediction, and measure it."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.camera import project
from tofpose.stages.tracking.constants import AT_EDGE, FOUND, NO_SIZE, NOT_FOUND
from tofpose.stages.tracking.records import WindowRuns, Windows


@jit
def _find(parent, i):
    """Root of run i in the union-find forest, compressing the path."""
    root = i
    while parent[root] != root:
        root = parent[root]
    while parent[i] != root:
        parent[i], i = root, parent[i]
    return root


@jit
def _window_runs(gray, u0, u1, v0, v1, threshold):
    """8-connected components of the pixels >= ``threshold`` in the window [u0, u1) x
    [v0, v1) of gray (H, W), as runs (a ``records.WindowRuns``): run q covers row
    ``row[q]`` (window coordinates), columns [c0[q], c1[q]), and belongs to component
    ``label[q]``; runs are in raster order and components are numbered 1.. in the raster
    order of their first pixel. Per component (index 1..n): area, the sums of the pixels'
    columns and rows, and the bounding box (x0, x1, y0, y1) inclusive, window
    coordinates.

    Runs joined by union-find, each root the earliest run of its component: a few
    operations per run instead of nine neighbour tests per pixel."""
    ph, pw = v1 - v0, u1 - u0
    cap = ph * ((pw + 1) // 2) + 1
    row = np.empty(cap, np.int64)
    c0 = np.empty(cap, np.int64)
    c1 = np.empty(cap, np.int64)
    parent = np.empty(cap, np.int64)
    n_runs = 0
    prev_a, prev_b = 0, 0  # the previous row's runs are [prev_a, prev_b)
    for r in range(ph):
        first = n_runs
        c = 0
        while c < pw:
            if gray[r + v0, c + u0] >= threshold:
                start = c
                while c < pw and gray[r + v0, c + u0] >= threshold:
                    c += 1
                q = n_runs
                row[q], c0[q], c1[q], parent[q] = r, start, c, q
                n_runs += 1
                for p in range(prev_a, prev_b):  # 8-adjacent: columns overlap within one
                    if max(c0[p], start) <= min(c1[p], c):
                        a, b = _find(parent, p), _find(parent, q)
                        if a < b:
                            parent[b] = a
                        elif b < a:
                            parent[a] = b
            c += 1
        prev_a, prev_b = first, n_runs
    label = np.zeros(n_runs, np.int64)
    n = 0
    for q in range(n_runs):
        root = _find(parent, q)
        if root == q:
            n += 1
            label[q] = n
        else:
            label[q] = label[root]
    area = np.zeros(n + 1, np.int64)
    su = np.zeros(n + 1)
    sv = np.zeros(n + 1)
    box = np.empty((n + 1, 4), np.int64)
    for k in range(n + 1):
        box[k, 0], box[k, 1], box[k, 2], box[k, 3] = pw, -1, ph, -1
    for q in range(n_runs):
        k, length = label[q], c1[q] - c0[q]
        area[k] += length
        su[k] += (c0[q] + c1[q] - 1) * length / 2  # whole numbers: exact in any order
        sv[k] += row[q] * length
        box[k, 0] = min(box[k, 0], c0[q])
        box[k, 1] = max(box[k, 1], c1[q] - 1)
        box[k, 2] = min(box[k, 2], row[q])
        box[k, 3] = max(box[k, 3], row[q])
    return WindowRuns(
        row=row[:n_runs],
        c0=c0[:n_runs],
        c1=c1[:n_runs],
        label=label,
        n=n,
        area=area,
        sum_u=su,
        sum_v=sv,
        box=box,
    )


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
        runs = _window_runs(gray, u0, u1, v0, v1, threshold)
        row, c0, c1, label, n_lab = runs.row, runs.c0, runs.c1, runs.label, runs.n
        area, su, sv, box = runs.area, runs.sum_u, runs.sum_v, runs.box
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
        x0, x1, y0, y1 = box[best, 0], box[best, 1], box[best, 2], box[best, 3]
        if x0 == 0 or y0 == 0 or x1 + 1 >= pw or y1 + 1 >= ph:
            status[j] = AT_EDGE
            continue
        px = np.empty(area[best], np.int64)
        sw, swu, swv, top = 0.0, 0.0, 0.0, -np.inf
        i = 0
        for q in range(row.shape[0]):  # the component's pixels in raster order
            if label[q] != best:
                continue
            r = row[q]
            for c in range(c0[q], c1[q]):
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
def any_shared(flat, starts, bbox):
    """Do two windows' pixel lists (flat indices, each sorted) share a pixel? bbox :
    (n, 4) int64 (x, y, w, h), each list's bounding box: lists whose boxes do not
    overlap share nothing and are not compared (the merge of two interleaved lists is
    a branch per pixel that the processor mispredicts)."""
    n = starts.shape[0] - 1
    for a in range(n):
        for b in range(a + 1, n):
            if not (
                bbox[a, 0] < bbox[b, 0] + bbox[b, 2]
                and bbox[b, 0] < bbox[a, 0] + bbox[a, 2]
                and bbox[a, 1] < bbox[b, 1] + bbox[b, 3]
                and bbox[b, 1] < bbox[a, 1] + bbox[a, 3]
            ):
                continue
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
def camera_windows(catalog, R, t, camera, margin_px, min_diameter_px):
    """``tracking.predict_windows`` as arrays: the windows (a ``records.Windows``: catalog
    indices (m,) of the reflectors to track, window bounds (m, 4) int64 (u0, u1, v0, v1),
    predicted centres (m, 2) px and diameters (m,) px) of the catalog (a
    ``records.CatalogRecord``; diameters 2 r) at the pose (R, t), seen by the camera (a
    ``records.CameraRecord``: its lens and image size). No windows when a reflector
    would be behind the camera."""
    xyz, radii, fx = catalog.xyz, catalog.radii_mm, camera.fx
    n = xyz.shape[0]
    centres = np.empty((n, 3))
    for i in range(n):  # R x + t by loops: BLAS's code is cold on every frame
        for a in range(3):
            centres[i, a] = R[a, 0] * xyz[i, 0] + R[a, 1] * xyz[i, 1] + R[a, 2] * xyz[i, 2] + t[a]
    d_px = np.empty(n)
    for i in range(n):
        if centres[i, 2] <= 0:
            return Windows(
                catalog_index=np.empty(0, np.int64),
                bounds=np.empty((0, 4), np.int64),
                centres=np.empty((0, 2)),
                diameters_px=np.empty(0),
            )
        d_px[i] = fx * (2.0 * radii[i]) / centres[i, 2]
    uv = project(centres, fx, camera.fy, camera.cx, camera.cy, camera.dist)
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
        use[i] = (
            d_px[i] >= min_diameter_px
            and gap >= 2.0
            and u0 >= 0
            and v0 >= 0
            and u1 <= camera.width
            and v1 <= camera.height
        )
    idx = np.flatnonzero(use)
    return Windows(catalog_index=idx, bounds=bounds[idx], centres=uv[idx], diameters_px=d_px[idx])
