"""§3.3's ellipse confirmation helpers as stated: a blob's binary mask, the split of its
closed contour into elliptical arcs (the angle, curvature and point conditions AC, CC,
PC) and the RMS distance of points from an ellipse (the residual that confirms a blob).

Same names, arguments and results as ``tofpose.stages.ellipses.kernels.ellipses``. A blob is its
flat
pixel indices (n,) into an image of ``width`` columns and its bounding box (x, y, bw, bh);
a contour is (P, 2) float (u, v); an ellipse is ((cx, cy), (a1, a2), angle_deg), a1 and a2
full axes along the directions angle and angle + 90 deg (OpenCV's ``RotatedRect``).
"""

from __future__ import annotations

import numpy as np


def blob_mask(pixels, x, y, bw, bh, width) -> np.ndarray:
    """§3.3's input: uint8 mask (bh + 2, bw + 2), 1 on the blob's pixels (flat indices
    (n,)) in its box (x, y, bw, bh) padded by one pixel; the mask's origin is the image
    pixel (x - 1, y - 1)."""
    rows, cols = np.divmod(np.asarray(pixels, np.int64), width)
    mask = np.zeros((bh + 2, bw + 2), np.uint8)
    mask[rows - y + 1, cols - x + 1] = 1
    return mask


def ellipse_rms_px(cx, cy, a1, a2, angle_deg, points) -> float:
    """The confirmation residual (§3.3, ours in its form): RMS over points (P, 2) of
    |r - r_e(theta)|, r and theta a point's polar coordinates about the centre in the
    ellipse's axes, r_e(theta) = ra rb / sqrt((rb cos theta)^2 + (ra sin theta)^2) the
    ellipse's radius along that ray (ra = a1 / 2, rb = a2 / 2); exact for circles. A
    point at the centre has theta = atan2(0, 0) = 0."""
    t = np.radians(angle_deg)
    du = np.asarray(points, float)[:, 0] - cx
    dv = np.asarray(points, float)[:, 1] - cy
    x = du * np.cos(t) + dv * np.sin(t)
    y = -du * np.sin(t) + dv * np.cos(t)
    theta = np.arctan2(y, x)
    ra, rb = a1 / 2, a2 / 2
    r_e = ra * rb / np.hypot(rb * np.cos(theta), ra * np.sin(theta))
    return float(np.sqrt(np.mean((np.hypot(x, y) - r_e) ** 2)))


def smoothed_contour(contour, smooth_sigma) -> np.ndarray:
    """The closed contour (P, 2) convolved along its length with a Gaussian of
    ``smooth_sigma`` points, truncated at 3 sigma and normalised, wrapping around (so
    pixel staircases do not count as curvature)."""
    n = len(contour)
    r = int(np.ceil(3 * smooth_sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / smooth_sigma) ** 2)
    k /= k.sum()
    wrapped = np.asarray(contour, float)[np.arange(-r, n + r) % n]
    return np.column_stack([np.convolve(wrapped[:, d], k, "valid") for d in range(2)])


def turning_angles_deg(smoothed) -> np.ndarray:
    """xi (P,): the turn, degrees in (-180, 180], from the tangent ending at point i to the
    tangent starting there, tangents of lag 2 (point i to point i + 2, wrapping)."""
    tangent = np.roll(smoothed, -2, axis=0) - smoothed
    ang = np.arctan2(tangent[:, 1], tangent[:, 0])
    d = ang - np.roll(ang, 2)
    return np.degrees(np.arctan2(np.sin(d), np.cos(d)))


def arc_points(contour, angle_deg, min_points, smooth_sigma):
    """§3.3's arc split (``ellipse.split_arcs``) as contour indices. contour (P, 2), P >=
    2 ``min_points``, ``min_points`` >= 1. The contour breaks where |xi| >
    ``angle_deg`` (a corner: AC) or xi turns against the sign of sum(xi) (the contour's
    dominant direction, + when the sum is 0) by more than 2 deg (a concave point: CC);
    xi from ``turning_angles_deg`` of ``smoothed_contour``. The points between two breaks,
    in contour order from the first break, are an arc when at least ``min_points`` (PC);
    no break at all gives one arc of every point. Returns index (M,) int64, starts
    (A + 1,) int64: arc a is ``contour[index[starts[a]:starts[a + 1]]]``."""
    n = len(contour)
    xi = turning_angles_deg(smoothed_contour(contour, smooth_sigma))
    dominant = np.sign(xi.sum()) or 1.0
    breaks = (np.abs(xi) > angle_deg) | (dominant * xi < -2.0)
    if not breaks.any():
        return np.arange(n, dtype=np.int64), np.array([0, n], np.int64)
    first = int(np.flatnonzero(breaks)[0])
    arcs, current = [], []
    for i in np.roll(np.arange(n), -first):
        if breaks[i]:
            if len(current) >= min_points:
                arcs.append(current)
            current = []
        else:
            current.append(int(i))
    if len(current) >= min_points:
        arcs.append(current)
    index = np.array([i for arc in arcs for i in arc], np.int64)
    starts = np.cumsum([0] + [len(arc) for arc in arcs]).astype(np.int64)
    return index, starts
