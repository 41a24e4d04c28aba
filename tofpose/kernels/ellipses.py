"""Helpers of the ellipse confirmation (§3.3), compiled: the blob's binary mask and the
RMS distance of edge points from a fitted ellipse (``tofpose.ellipse``)."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit
from tofpose.kernels.indexing import row_col


@jit
def blob_mask(pixels, x, y, bw, bh, width):
    """uint8 mask (bh + 2, bw + 2) of a blob's pixels (flat indices) in its box (x, y,
    bw, bh) padded by one pixel; the mask's origin is (x - 1, y - 1)."""
    m = np.zeros((bh + 2, bw + 2), np.uint8)
    inv_width = 1.0 / width
    for p in pixels:
        r, c = row_col(p, width, inv_width)
        m[r - y + 1, c - x + 1] = 1
    return m


@jit
def ellipse_rms_px(cx, cy, a1, a2, angle_deg, points):
    """RMS radial distance of points (P, 2) from the ellipse ((cx, cy), (a1, a2), angle):
    along the ray from the centre, |r_point - r_ellipse(theta)|, exact for circles."""
    t = np.radians(angle_deg)
    ct, st = np.cos(t), np.sin(t)
    ra, rb = a1 / 2, a2 / 2
    s = 0.0
    n = points.shape[0]
    for i in range(n):
        du, dv = points[i, 0] - cx, points[i, 1] - cy
        x = du * ct + dv * st
        y = -du * st + dv * ct
        r = np.hypot(x, y)
        th = np.arctan2(y, x)
        r_e = ra * rb / np.sqrt((rb * np.cos(th)) ** 2 + (ra * np.sin(th)) ** 2)
        s += (r - r_e) ** 2
    return np.sqrt(s / n)
