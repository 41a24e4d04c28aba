"""§3.4 as stated: a blob's centroid (Eq. 19, with our weights) and its radial distance
(Eq. 20, the median of its pixels' ranges on the centroid's line of sight).

Shapes: gray, distance (H, W); a blob is its flat pixel indices (n,) and its bounding box
(x, y, w, h); ``owner`` (H, W) int, the index of the blob owning each pixel (-1 none).
"""

from __future__ import annotations

import cv2
import numpy as np

from tofpose.stages.extraction.constants import PLATEAU_MIN_PX, PLATEAU_RATIO


def surround_level(gray, bbox, owner=None, j=0, frame_level=0.0) -> float:
    """The median gray of the ring between the blob's box grown by 1 and by 3 px, other
    blobs' pixels left out; ``frame_level`` where the ring is empty."""
    h, w = gray.shape
    x, y, bw, bh = bbox
    ring = np.zeros((h, w), bool)
    ring[max(y - 3, 0) : y + bh + 3, max(x - 3, 0) : x + bw + 3] = True
    ring[max(y - 1, 0) : y + bh + 1, max(x - 1, 0) : x + bw + 1] = False
    if owner is not None:
        ring &= (owner == -1) | (owner == j)
    return float(np.median(gray[ring])) if ring.any() else float(frame_level)


def centroid_weights(gray, pixels, bbox, level, coverage=True):
    """The weights of Eq. 19 over the blob's box grown by 2 px: (weights (h', w'), x0,
    y0, support (h', w') bool). Support: the blob dilated by one pixel. Weights: the
    value above ``level`` (Eq. 19, intensity), or with ``coverage`` and a plateau of at
    least ``PLATEAU_MIN_PX`` members at ``PLATEAU_RATIO`` of their neighbourhood's
    largest member, that value over the neighbourhood's largest member, clipped to
    [0, 1] (a whole-covered pixel counts 1, an edge pixel its covered fraction)."""
    h, w = gray.shape
    x, y, bw, bh = bbox
    y0, y1, x0, x1 = max(y - 2, 0), min(y + bh + 2, h), max(x - 2, 0), min(x + bw + 2, w)
    rows, cols = np.divmod(np.asarray(pixels), w)
    member = np.zeros((y1 - y0, x1 - x0), np.uint8)
    member[rows - y0, cols - x0] = 1
    support = cv2.dilate(member, np.ones((3, 3), np.uint8)).astype(bool)
    value = np.maximum(gray[y0:y1, x0:x1] - level, 0.0).astype(np.float32)
    member_value = np.where(member > 0, value, 0).astype(np.float32)
    local_max = cv2.dilate(member_value, np.ones((3, 3), np.uint8))
    plateau = (
        (member > 0) & (member_value > 0) & (member_value >= np.float32(PLATEAU_RATIO) * local_max)
    )
    if coverage and plateau.sum() >= PLATEAU_MIN_PX:
        with np.errstate(divide="ignore", invalid="ignore"):
            weights = np.clip(value / local_max, 0, 1)
        weights[~np.isfinite(weights)] = 0
    else:
        weights = value
    return weights, x0, y0, support


def blob_centroid(gray, pixels, bbox, level, owner=None, j=0, coverage=True) -> np.ndarray:
    """Eq. 19: (u, v) px, the weighted mean over the support (other blobs' pixels left
    out) of the pixel coordinates (``centroid_weights``)."""
    weights, x0, y0, support = centroid_weights(gray, pixels, bbox, level, coverage)
    if owner is not None:
        o = owner[y0 : y0 + support.shape[0], x0 : x0 + support.shape[1]]
        support &= (o == -1) | (o == j)
    rr, cc = np.nonzero(support)
    wt = weights[support].astype(float)
    return np.array([(wt * (cc + x0)).sum() / wt.sum(), (wt * (rr + y0)).sum() / wt.sum()])


def blob_range(distance, pixels, pixel_bearings, centre_bearing) -> float:
    """Eq. 20 as we measure it: the median over the blob's pixels with a range of
    ``rho_p (e_p . e_c)``, each pixel's point projected on the centroid's line of sight.
    pixel_bearings (H, W, 3) unit vectors; centre_bearing (3,)."""
    w = distance.shape[1]
    rows, cols = np.divmod(np.asarray(pixels), w)
    d = distance[rows, cols]
    ok = np.isfinite(d)
    return float(np.median(d[ok] * (pixel_bearings[rows[ok], cols[ok]] @ centre_bearing)))
