"""Centroids (Eq. 19) and radial distances (Eq. 20) of measured blobs, all blobs in one
call; the arithmetic of ``tofpose.stages.extraction.extraction.measure_blobs``, whose docstring
gives the
method (coverage weights over the blob dilated by one pixel, median of the ranges
projected on the centroid's line of sight)."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.indexing import row_col, run_end
from tofpose.core.kernels.stats import median_inplace
from tofpose.stages.extraction.constants import PLATEAU_MIN_PX, PLATEAU_RATIO
from tofpose.stages.extraction.records import OwnerMap


@jit
def blob_centroids(flat, starts, bbox, gray, background, coverage, owners):
    """Centroid (u, v) px of each blob.

    flat, starts : blob j's pixels are ``flat[starts[j]:starts[j + 1]]`` (flat indices);
    bbox : (n, 4) int64 (x, y, w, h); gray : (H, W) float32; background : (n,) each
    blob's surround level (``mixed_pixels.blob_surrounds``), counts; coverage : coverage
    weights for a blob with a plateau of whole-covered pixels (``PLATEAU_MIN_PX`` at
    ``PLATEAU_RATIO``) and intensity weights for the others (else intensity for all, Eq.
    19 as written); owners : ``owner_map``'s ``records.OwnerMap`` (the blob owning
    each pixel, read when used). Returns (n, 2) float64.
    """
    h, w = gray.shape
    n = bbox.shape[0]
    out = np.empty((n, 2))
    inv_w = 1.0 / w
    for j in range(n):
        bg = np.float32(background[j])
        x, y, bw, bh = bbox[j, 0], bbox[j, 1], bbox[j, 2], bbox[j, 3]
        y0, y1 = max(y - 2, 0), min(y + bh + 2, h)
        x0, x1 = max(x - 2, 0), min(x + bw + 2, w)
        ph, pw = y1 - y0, x1 - x0
        # the members' background-subtracted values (>= 0), -1 elsewhere and on a border
        # of one pixel around the box; filled run by run (contiguous in both arrays)
        member = np.full((ph + 2, pw + 2), np.float32(-1.0))
        i, end = starts[j], starts[j + 1]
        while i < end:
            r, c = row_col(flat[i], w, inv_w)
            e = run_end(flat, i, end, w - c)
            m_row, g_row = member[r - y0 + 1], gray[r]
            for q in range(e - i):
                m_row[c - x0 + 1 + q] = max(g_row[c + q] - bg, np.float32(0.0))
            i = e
        # the largest member value around each pixel (3 x 3, separable: rows, then
        # columns): >= 0 on the one-pixel ring (the blob dilated by one pixel), where it
        # is the coverage denominator; -1 elsewhere
        row_max = np.empty((ph + 2, pw), np.float32)
        for r in range(ph + 2):
            for c in range(pw):
                row_max[r, c] = max(max(member[r, c], member[r, c + 1]), member[r, c + 2])
        # a plateau of whole-covered pixels (members at >= PLATEAU_RATIO of their 3 x 3
        # neighbourhood's largest member value) is what coverage weights measure; a spot
        # without one (a small disc, or a blurred one) is all edge, where coverage is the
        # support's outline and intensity weights (Eq. 19) are the unbiased centre
        use_coverage = False
        if coverage:
            n_full = 0
            for r in range(ph):
                a_row, b_row, c_row = row_max[r], row_max[r + 1], row_max[r + 2]
                m_row = member[r + 1]
                for c in range(pw):
                    mv = m_row[c + 1]
                    if mv > 0:
                        local_max = max(max(a_row[c], b_row[c]), c_row[c])
                        if mv >= np.float32(PLATEAU_RATIO) * local_max:
                            n_full += 1
            use_coverage = n_full >= PLATEAU_MIN_PX
        # row by row: the weights without a branch (the compiler vectorises the loop; 0
        # off the dilated blob and on a neighbour's pixels), then the sums in pixel order
        # (adding 0 changes no sum: they are >= 0)
        wt = np.empty(pw)
        sw, su, sv = 0.0, 0.0, 0.0
        for r in range(ph):
            g_row = gray[r + y0]
            a_row, b_row, c_row = row_max[r], row_max[r + 1], row_max[r + 2]
            for c in range(pw):
                local_max = max(max(a_row[c], b_row[c]), c_row[c])
                value = max(g_row[c + x0] - bg, np.float32(0.0))
                if use_coverage:  # clip(value / local_max, 0, 1); x / 0 -> 1, 0 / 0 -> 0
                    q = value / (local_max if local_max > 0 else np.float32(1.0))
                    covered = min(max(q, np.float32(0.0)), np.float32(1.0))
                    lone = np.float32(1.0) if value > 0 else np.float32(0.0)
                    v = covered if local_max > 0 else lone
                else:
                    v = value
                wt[c] = float(v) if local_max >= 0 else 0.0
            if owners.used:
                for c in range(pw):
                    o = owners.owner[r + y0 - owners.y0, c + x0 - owners.x0]
                    if o != -1 and o != j:
                        wt[c] = 0.0
            row_v = float(r + y0)
            for c in range(pw):
                sw += wt[c]
                su += wt[c] * (c + x0)
                sv += wt[c] * row_v
        if sw <= 0:  # no weight anywhere: the plain mean of the ring
            sw, su, sv = 0.0, 0.0, 0.0
            for r in range(ph):
                for c in range(pw):
                    local_max = max(max(row_max[r, c], row_max[r + 1, c]), row_max[r + 2, c])
                    o = owners.owner[r + y0 - owners.y0, c + x0 - owners.x0] if owners.used else -1
                    if local_max >= 0 and (o == -1 or o == j):
                        sw += 1.0
                        su += c + x0
                        sv += r + y0
        out[j, 0] = su / sw
        out[j, 1] = sv / sw
    return out


@jit
def blob_ranges(flat, starts, distance_flat, bearings_flat, centre_bearings):
    """Radial distance of each blob (Eq. 20 variant): the median over its valid pixels of
    ``rho_p * (e_p . e_c)``; NaN when no pixel has a range.

    distance_flat : (H * W,) float32 mm; bearings_flat : (H * W, 3) unit bearings of the
    pixels; centre_bearings : (n, 3) of the centroids. Returns (n,) float64.
    """
    n = centre_bearings.shape[0]
    out = np.empty(n)
    for j in range(n):
        a, b = starts[j], starts[j + 1]
        along = np.empty(b - a)
        m = 0
        ex, ey, ez = centre_bearings[j, 0], centre_bearings[j, 1], centre_bearings[j, 2]
        for i in range(a, b):
            p = flat[i]
            d = distance_flat[p]
            if np.isfinite(d):
                along[m] = d * (
                    bearings_flat[p, 0] * ex + bearings_flat[p, 1] * ey + bearings_flat[p, 2] * ez
                )
                m += 1
        if m == 0:
            out[j] = np.nan
            continue
        out[j] = median_inplace(along[:m])
    return out


@jit
def owner_map(flat, starts, bbox, h, w):
    """Index of the blob owning each pixel (-1: none) over the part of the (H, W) image
    that holds every blob's box grown by 2 px, and whether it is needed: only when a
    blob's box (n, 4) (x, y, w, h) grown by 3 px (the reach of its surround ring,
    ``constants.SURROUND_OUTER_PX``) meets another's box (the usual case is that none
    does, and nothing needs excluding). The ring of a blob must not reach into a
    neighbour's pixels (markers 7 and 8 split apart touch each other), or that
    neighbour's light pulls the centroid towards it. Returns owner (h', w') int32, its
    top-left pixel (x0, y0) in the image, and whether it is used: a
    ``records.OwnerMap``."""
    n = bbox.shape[0]
    near = False
    for a in range(n):
        for b in range(n):
            if a != b and (
                bbox[a, 0] - 3 < bbox[b, 0] + bbox[b, 2]
                and bbox[b, 0] - 3 < bbox[a, 0] + bbox[a, 2]
                and bbox[a, 1] - 3 < bbox[b, 1] + bbox[b, 3]
                and bbox[b, 1] - 3 < bbox[a, 1] + bbox[a, 3]
            ):
                near = True
    if not near:
        return OwnerMap(owner=np.full((1, 1), -1, np.int32), x0=0, y0=0, used=False)
    x0, y0, x1, y1 = w, h, 0, 0
    for j in range(n):
        x0 = min(x0, max(bbox[j, 0] - 2, 0))
        y0 = min(y0, max(bbox[j, 1] - 2, 0))
        x1 = max(x1, min(bbox[j, 0] + bbox[j, 2] + 2, w))
        y1 = max(y1, min(bbox[j, 1] + bbox[j, 3] + 2, h))
    owner = np.full((y1 - y0, x1 - x0), -1, np.int32)
    inv_w = 1.0 / w
    for j in range(n):
        for i in range(starts[j], starts[j + 1]):
            r, c = row_col(flat[i], w, inv_w)
            owner[r - y0, c - x0] = j
    return OwnerMap(owner=owner, x0=x0, y0=y0, used=True)
