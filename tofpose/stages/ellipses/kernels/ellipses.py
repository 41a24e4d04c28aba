"""Helpers of the ellipse confirmation (§3.3), compiled: the blob's binary mask and the
RMS distance of edge points from a fitted ellipse (``tofpose.stages.ellipses.ellipse``)."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.indexing import row_col


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
    along the ray from the centre, |r_point - r_ellipse(theta)|, exact for circles.

    In the ellipse's axes a point is (x, y) = r (cos theta, sin theta), and the ellipse's
    radius along that ray is ra rb / sqrt((rb cos theta)^2 + (ra sin theta)^2) =
    ra rb r / sqrt((rb x)^2 + (ra y)^2): no angle is needed (a point at the centre takes
    the radius along the first axis, theta = atan2(0, 0) = 0)."""
    t = np.radians(angle_deg)
    ct, st = np.cos(t), np.sin(t)
    ra, rb = a1 / 2, a2 / 2
    s = 0.0
    n = points.shape[0]
    for i in range(n):
        du, dv = points[i, 0] - cx, points[i, 1] - cy
        x = du * ct + dv * st
        y = -du * st + dv * ct
        r = np.sqrt(x * x + y * y)
        q = np.sqrt((rb * x) ** 2 + (ra * y) ** 2)
        r_e = ra * rb * r / q if q > 0 else ra
        s += (r - r_e) ** 2
    return np.sqrt(s / n)


@jit
def arc_points(contour, angle_deg, min_points, smooth_sigma):
    """The arcs of ``ellipse.split_arcs`` as contour indices: arc a holds the points
    ``index[starts[a]:starts[a + 1]]`` (in contour order from the first break).

    contour : (P, 2) float64 closed contour, P >= 2 min_points. The contour smoothed
    along its length (Gaussian of ``smooth_sigma`` points, wrapped), the turning angle xi
    between tangents of lag 2 in degrees wrapped to (-180, 180]; breaks where |xi| >
    ``angle_deg`` (AC) or xi turns against the sign of sum(xi) by more than 2 deg (CC);
    runs of fewer than ``min_points`` points between breaks dropped (PC). No break at all
    gives one arc of every point in order. Returns index (M,) int64, starts (A + 1,)."""
    n = contour.shape[0]
    r = int(np.ceil(3 * smooth_sigma))
    k = np.empty(2 * r + 1)
    for i in range(2 * r + 1):
        k[i] = np.exp(-0.5 * ((i - r) / smooth_sigma) ** 2)
    k /= k.sum()
    sm = np.empty((n, 2))
    for i in range(n):
        for d in range(2):
            s = 0.0
            for m in range(2 * r + 1):
                s += contour[(i + m - r) % n, d] * k[2 * r - m]
            sm[i, d] = s
    lag = 2
    ang = np.empty(n)
    for i in range(n):
        j = (i + lag) % n
        ang[i] = np.arctan2(sm[j, 1] - sm[i, 1], sm[j, 0] - sm[i, 0])
    xi = np.empty(n)
    for i in range(n):
        d = ang[i] - ang[(i - lag) % n]
        xi[i] = np.degrees(np.arctan2(np.sin(d), np.cos(d)))
    total = xi.sum()
    dominant = 1.0 if total >= 0 else -1.0
    if total == 0:
        dominant = 1.0
    breaks = np.empty(n, np.bool_)
    first = -1
    for i in range(n):
        breaks[i] = abs(xi[i]) > angle_deg or dominant * xi[i] < -2.0
        if breaks[i] and first < 0:
            first = i
    index = np.empty(n, np.int64)
    starts = np.zeros(n + 1, np.int64)
    if first < 0:
        for i in range(n):
            index[i] = i
        starts[1] = n
        return index, starts[:2]
    n_arcs, m, run = 0, 0, 0
    for s in range(n):
        i = (first + s) % n
        if breaks[i]:
            if run < min_points:
                m -= run  # too short: drop the run
            elif run:
                n_arcs += 1
                starts[n_arcs] = m
            run = 0
        else:
            index[m] = i
            m += 1
            run += 1
    if run >= min_points:
        n_arcs += 1
        starts[n_arcs] = m
    else:
        m -= run
    return index[:m], starts[: n_arcs + 1]
