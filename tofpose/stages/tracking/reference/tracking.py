"""Tracking mode as stated (ours, beyond the paper: ``tofpose.stages.tracking.tracking``): a window
around
each catalog reflector's predicted image (Eq. 7 with the lens model), and in each window
the thresholded frame's 8-connected component nearest the prediction, of plausible size,
away from the window's edge, measured by Eq. 19.

Same names, arguments and results as ``tofpose.stages.tracking.kernels.tracking``. Windows are [u0,
u1) x
[v0, v1) pixel bounds (n, 4) int64 as (u0, u1, v0, v1); pixels are (u, v) = (column,
row); a blob is its flat pixel indices, raster order.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial.distance import cdist

from tofpose.core.reference.camera import project
from tofpose.stages.tracking.constants import AT_EDGE, FOUND, NO_SIZE, NOT_FOUND
from tofpose.stages.tracking.records import WindowRuns, Windows

#: predicted discs closer than this (px, rim to rim) merge into one blob: not tracked
MIN_GAP_PX = 2.0


def camera_windows(catalog, R, t, camera, margin_px, min_diameter_px):
    """``tracking.predict_windows`` as arrays. catalog : xyz (N, 3) mm and radii_mm (N,)
    (the diameters D are 2 r); the pose (R (3, 3), t (3,)); camera : the lens (K, dist)
    and the image size (width x height) of a ``core.records.CameraRecord``, read by field
    name.

    Each reflector's centre R x + t is projected (Eq. 7, ``core.reference.camera.project``);
    its predicted diameter is fx D / z px. Its window is the disc plus ``margin_px``:
    [floor(u - h), ceil(u + h) + 1) x [floor(v - h), ceil(v + h) + 1), h = d / 2 +
    margin. A reflector is tracked when its diameter is at least ``min_diameter_px``,
    its rim is at least ``MIN_GAP_PX`` from every other's (centre distance minus half
    the two diameters) and its window lies in the image. Returns the ``Windows``: the
    catalog indices (m,) int64 of those, their windows (m, 4) int64, predicted centres
    (m, 2) px and diameters (m,) px; nothing when any reflector is behind the camera."""
    centres = np.asarray(catalog.xyz, float) @ np.asarray(R, float).T + np.asarray(t, float)
    if np.any(centres[:, 2] <= 0):
        return Windows(
            catalog_index=np.empty(0, np.int64),
            bounds=np.empty((0, 4), np.int64),
            centres=np.empty((0, 2)),
            diameters_px=np.empty(0),
        )
    d_px = camera.fx * (2.0 * np.asarray(catalog.radii_mm, float)) / centres[:, 2]
    uv = project(centres, camera.K, camera.dist)
    gap = cdist(uv, uv) - 0.5 * (d_px[:, None] + d_px[None, :])
    np.fill_diagonal(gap, np.inf)
    half = 0.5 * d_px + margin_px
    bounds = np.column_stack(
        (
            np.floor(uv[:, 0] - half),
            np.ceil(uv[:, 0] + half) + 1,
            np.floor(uv[:, 1] - half),
            np.ceil(uv[:, 1] + half) + 1,
        )
    )
    bounds = bounds.astype(np.int64)
    use = (
        (d_px >= min_diameter_px)
        & (gap.min(axis=1, initial=np.inf) >= MIN_GAP_PX)
        & (bounds[:, 0] >= 0)
        & (bounds[:, 2] >= 0)
        & (bounds[:, 1] <= camera.width)
        & (bounds[:, 3] <= camera.height)
    )
    idx = np.flatnonzero(use).astype(np.int64)
    return Windows(catalog_index=idx, bounds=bounds[idx], centres=uv[idx], diameters_px=d_px[idx])


def window_components(gray, u0, u1, v0, v1, threshold):
    """The 8-connected components of the window's pixels >= ``threshold`` (compared as
    float64), by ``cv2.connectedComponentsWithStats``, renumbered 1.. in the raster
    order of their first pixel. Returns labels (v1 - v0, u1 - u0) int (0: none), n, and
    per component (index 0..n, 0 unused) area (n + 1,), unweighted centroid (n + 1, 2)
    (u, v) and box (n + 1, 4) (x, y, w, h), window coordinates."""
    patch = np.asarray(gray)[v0:v1, u0:u1].astype(np.float64)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(
        (patch >= float(threshold)).astype(np.uint8), connectivity=8
    )
    first = [np.flatnonzero(labels.ravel() == k)[0] for k in range(1, n)]
    order = np.argsort(np.array(first, np.int64)) + 1  # OpenCV's numbers by first pixel
    renumber = np.zeros(n, np.int64)
    renumber[order] = np.arange(1, n)
    keep = np.concatenate(([0], order))
    return (
        renumber[labels],
        n - 1,
        stats[keep, cv2.CC_STAT_AREA].astype(np.int64),
        cents[keep],
        stats[keep, :4].astype(np.int64),
    )


def _window_runs(gray, u0, u1, v0, v1, threshold):
    """``window_components`` in the kernel's form (a ``WindowRuns``): the components as
    runs, run q on row
    ``row[q]`` (window coordinates) over columns [c0[q], c1[q]) of component
    ``label[q]``, runs in raster order; n; per component (0..n) area, the sums of the
    pixels' columns and rows, and the box (x0, x1, y0, y1) inclusive (component 0: the
    empty box (pw, -1, ph, -1))."""
    labels, n, area, cents, stats = window_components(gray, u0, u1, v0, v1, threshold)
    ph, pw = labels.shape
    padded = np.pad(labels, ((0, 0), (1, 1)))
    row, c0, c1 = [], [], []
    for r in range(ph):
        edges = np.flatnonzero((padded[r, 1:] > 0) != (padded[r, :-1] > 0))
        row += [r] * (len(edges) // 2)
        c0 += edges[0::2].tolist()
        c1 += edges[1::2].tolist()
    row, c0, c1 = (np.array(v, np.int64) for v in (row, c0, c1))
    box = np.column_stack(
        (stats[:, 0], stats[:, 0] + stats[:, 2] - 1, stats[:, 1], stats[:, 1] + stats[:, 3] - 1)
    )
    box[0] = (pw, -1, ph, -1)
    area[0] = 0
    sums = np.vstack(([0.0, 0.0], np.round(cents[1:] * area[1:, None])))  # whole numbers
    return WindowRuns(
        row=row,
        c0=c0,
        c1=c1,
        label=labels[row, c0],
        n=n,
        area=area,
        sum_u=sums[:, 0],
        sum_v=sums[:, 1],
        box=box,
    )


def search_windows(gray, bounds, centres, diameters, threshold, background):
    """Each window's reflector. gray (H, W); bounds (n, 4) int64 windows; centres (n, 2)
    predicted centres px; diameters (n,) predicted diameters px; threshold counts (the
    last acquisition's I_t); background counts.

    A window's component (``window_components``) is, among those whose area lies in
    [max(1, a / 4), max(4, 4 a)], a = pi (d / 2)^2 the predicted disc's area, the one
    whose unweighted centroid is nearest the prediction (the first in numbering on a
    tie): ``NO_SIZE`` when none is, ``NOT_FOUND`` when the window holds no component at
    all, ``AT_EDGE`` when its box touches the window's border. Returns status (n,)
    int64, bbox (n, 4) int64 global (x, y, w, h), peak (n,) counts, centroid (n, 2) the
    Eq. 19 centroid with weights max(I - background, 1e-9) (NaN unless found), starts
    (n + 1,) and flat: window j's pixels (flat, raster order) are
    ``flat[starts[j]:starts[j + 1]]`` (none unless found)."""
    gray = np.asarray(gray)
    h, w = gray.shape
    n = len(bounds)
    status = np.full(n, NOT_FOUND, np.int64)
    bbox = np.zeros((n, 4), np.int64)
    peak = np.zeros(n)
    centroid = np.full((n, 2), np.nan)
    pieces = [np.empty(0, np.int64) for _ in range(n)]
    for j, (u0, u1, v0, v1) in enumerate(np.asarray(bounds, np.int64).tolist()):
        labels, n_lab, area, cents, box = window_components(gray, u0, u1, v0, v1, threshold)
        if n_lab == 0:
            continue
        a = np.pi * (0.5 * diameters[j]) ** 2
        sized = [
            k for k in range(1, n_lab + 1) if max(1.0, 0.25 * a) <= area[k] <= max(4.0, 4.0 * a)
        ]
        if not sized:
            status[j] = NO_SIZE
            continue
        near = [np.hypot(*(cents[k] - (centres[j] - [u0, v0]))) for k in sized]
        best = sized[int(np.argmin(near))]
        x, y, bw, bh = box[best]
        if x == 0 or y == 0 or x + bw >= u1 - u0 or y + bh >= v1 - v0:
            status[j] = AT_EDGE
            continue
        rows, cols = np.nonzero(labels == best)
        values = gray[rows + v0, cols + u0].astype(np.float64)
        wt = np.maximum(values - background, 1e-9)
        status[j] = FOUND
        bbox[j] = (x + u0, y + v0, bw, bh)
        peak[j] = values.max()
        centroid[j] = (wt @ (cols + u0) / wt.sum(), wt @ (rows + v0) / wt.sum())
        pieces[j] = ((rows + v0) * w + cols + u0).astype(np.int64)
    starts = np.cumsum([0] + [len(p) for p in pieces]).astype(np.int64)
    return status, bbox, peak, centroid, starts, np.concatenate(pieces).astype(np.int64)


def any_shared(flat, starts, bbox) -> bool:
    """Do two windows' pixel lists (``flat[starts[j]:starts[j + 1]]``) share a pixel (one
    blob serving two reflectors)? bbox (n, 4), each list's bounding box, only spares the
    kernel work: the answer does not depend on it."""
    lists = [flat[starts[j] : starts[j + 1]] for j in range(len(starts) - 1)]
    return any(
        np.intersect1d(lists[a], lists[b]).size
        for a in range(len(lists))
        for b in range(a + 1, len(lists))
    )
