"""§3.4 in one call: combine the frame with the consistent persistence history and
measure the kept blobs' centroids (Eq. 19) and ranges (Eq. 20) on the combined frames.
The arithmetic of ``Persistence.apply`` followed by ``extraction.measure_blobs``."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit
from tofpose.kernels.camera import bearings
from tofpose.kernels.centroids import blob_centroids, blob_ranges, owner_map
from tofpose.kernels.persistence import (
    column_medians,
    consistent,
    counter_medians,
    mean_in_boxes,
)


@jit
def persist_and_measure(
    gray, distance, flat, starts, bbox, centroids, hist_gray, hist_dist, hist_mask,
    hist_cent, n_hist, tol_px, c_min, background, fx, fy, cx, cy, dist, pixel_bearings,
    mean_buf, med_buf,
):  # fmt: skip
    """The frame's blobs (pixels ``flat[starts[j]:starts[j + 1]]``, boxes (n, 4) (x, y,
    w, h), single-frame centroids (n, 2), NaN allowed) combined with the history (newest
    first as tuples, the first ``n_hist`` real: ``Persistence.history``) and measured.

    Returns n_used (consistent history frames combined), motion (the history was cut),
    keep (n,) bool (counter C >= c_min, or every blob while fewer than c_min frames are
    combined), mean_gray (H, W) float32, med_distance (H, W) float32, uv (n, 2) and rho
    (n,) of the kept blobs (NaN for the others): coverage-weighted centroids on I-bar and
    ranges on D-bar along each centroid's line of sight.

    With one frame, mean_gray and med_distance are the frame's gray and distance. With
    more, they are the scratch frames ``mean_buf`` and ``med_buf`` (H, W) float32
    (``Persistence`` owns them and lends them to every frame: copying two whole frames
    cost more than the rest of this call at far range), holding I-bar inside the boxes
    grown by 2 px and D-bar at the kept blobs' pixels, the only places anything reads;
    elsewhere they hold whatever an earlier frame left there."""
    h, w = gray.shape
    n = starts.shape[0] - 1
    n_used, motion = 0, False
    for f in range(n_hist):
        if consistent(centroids, hist_cent[f], tol_px):
            n_used += 1
        else:
            motion = True
            break
    frames = 1 + n_used
    keep = np.ones(n, np.bool_)
    mean_gray = gray
    med_dist = distance
    if frames > 1 and n > 0:
        if frames >= c_min:
            keep = counter_medians(hist_mask, n_used, flat, starts, 1) >= c_min
        mean_gray = mean_in_boxes(gray, hist_gray, n_used, bbox, mean_buf)
        med_dist = med_buf
        kidx = np.empty(flat.shape[0], np.int64)
        m = 0
        for j in range(n):
            if keep[j]:
                for i in range(starts[j], starts[j + 1]):
                    kidx[m] = flat[i]
                    m += 1
        stack = np.empty((frames, m), np.float32)
        src = distance.reshape(-1)
        for i in range(m):
            stack[0, i] = src[kidx[i]]
        for f in range(n_used):
            older = hist_dist[f].reshape(-1)
            for i in range(m):
                stack[f + 1, i] = older[kidx[i]]
        med = column_medians(stack)
        out = med_dist.reshape(-1)
        for i in range(m):
            out[kidx[i]] = med[i]

    # the kept blobs as their own pixel lists, then Eqs. 19-20
    kept = np.flatnonzero(keep)
    k_starts = np.zeros(kept.shape[0] + 1, np.int64)
    for a in range(kept.shape[0]):
        j = kept[a]
        k_starts[a + 1] = k_starts[a] + starts[j + 1] - starts[j]
    k_flat = np.empty(k_starts[-1], np.int64)
    k_bbox = np.empty((kept.shape[0], 4), np.int64)
    for a in range(kept.shape[0]):
        j = kept[a]
        k_flat[k_starts[a] : k_starts[a + 1]] = flat[starts[j] : starts[j + 1]]
        k_bbox[a] = bbox[j]
    owner, ox, oy, use_owner = owner_map(k_flat, k_starts, k_bbox, h, w)
    k_uv = blob_centroids(k_flat, k_starts, k_bbox, mean_gray, background, True, owner, ox,
                          oy, use_owner)  # fmt: skip
    k_rho = blob_ranges(k_flat, k_starts, med_dist.reshape(-1), pixel_bearings,
                        bearings(k_uv, fx, fy, cx, cy, dist))  # fmt: skip
    uv = np.full((n, 2), np.nan)
    rho = np.full(n, np.nan)
    for a in range(kept.shape[0]):
        uv[kept[a]] = k_uv[a]
        rho[kept[a]] = k_rho[a]
    return n_used, motion, keep, mean_gray, med_dist, uv, rho
