"""The compiled helpers of §3.3: the arc split (``kernels.ellipses.arc_points`` behind
``ellipse.split_arcs``) against the NumPy statement it replaced, on random blob contours:
one to three overlapping ellipses (merged markers), some with speckle; and the RMS
distance from an ellipse."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from tofpose.ellipse import blob_contour, split_arcs


def _split_arcs_reference(contour, angle_deg=40.0, min_points=6, smooth_sigma=2.0):
    n = len(contour)
    if n < 2 * min_points:
        return [contour] if n >= min_points else []
    pts = contour.astype(np.float64)
    r = int(np.ceil(3 * smooth_sigma))
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / smooth_sigma) ** 2)
    k /= k.sum()
    wrap = np.vstack((pts[-r:], pts, pts[:r]))
    sm = np.column_stack([np.convolve(wrap[:, i], k, "valid") for i in range(2)])
    tangent = np.roll(sm, -2, axis=0) - sm
    ang = np.arctan2(tangent[:, 1], tangent[:, 0])
    xi = np.degrees(np.angle(np.exp(1j * (ang - np.roll(ang, 2)))))
    dominant = np.sign(np.sum(xi)) or 1.0
    breaks = (np.abs(xi) > angle_deg) | (dominant * xi < -2.0)
    if not np.any(breaks):
        return [contour]
    start = int(np.flatnonzero(breaks)[0])
    arcs, current = [], []
    for j in np.roll(np.arange(n), -start):
        if breaks[j]:
            if len(current) >= min_points:
                arcs.append(contour[current])
            current = []
        else:
            current.append(int(j))
    if len(current) >= min_points:
        arcs.append(contour[current])
    return arcs


def test_arcs_equal_the_numpy_statement_on_random_contours():
    rng = np.random.default_rng(0)
    n_arcs = 0
    for _ in range(600):
        mask = np.zeros((40, 60), np.uint8)
        for _ in range(rng.integers(1, 4)):
            centre = (float(rng.uniform(10, 50)), float(rng.uniform(10, 30)))
            axes = (float(rng.uniform(4, 25)), float(rng.uniform(4, 20)))
            cv2.ellipse(mask, (centre, axes, float(rng.uniform(0, 180))), 1, -1)
        if rng.random() < 0.3:
            mask[rng.random(mask.shape) < 0.05] = 1
        contour = blob_contour(mask)
        for min_points in (4, 6, 9):
            want = _split_arcs_reference(contour, min_points=min_points)
            got = split_arcs(contour, min_points=min_points)
            assert len(got) == len(want)
            for a, b in zip(got, want, strict=True):
                np.testing.assert_array_equal(a, b)
            n_arcs += len(want)
    assert n_arcs > 1000  # the contours do break into arcs (not one arc each)


def test_ellipse_residual_equals_the_angular_statement():
    """The radius along each point's ray without angles (``ellipse_rms_px``) against
    r_e(theta) = ra rb / sqrt((rb cos theta)^2 + (ra sin theta)^2), theta = atan2."""
    from tofpose.kernels.ellipses import ellipse_rms_px

    rng = np.random.default_rng(4)
    for _ in range(500):
        cx, cy = rng.uniform(0, 300, 2)
        a1, a2 = rng.uniform(2, 60, 2)
        ang = rng.uniform(0, 180)
        pts = np.column_stack([cx + rng.normal(0, 20, 40), cy + rng.normal(0, 20, 40)])
        pts[0] = (cx, cy)  # one at the centre: theta = atan2(0, 0) = 0
        t = np.radians(ang)
        du, dv = pts[:, 0] - cx, pts[:, 1] - cy
        x, y = du * np.cos(t) + dv * np.sin(t), -du * np.sin(t) + dv * np.cos(t)
        theta = np.arctan2(y, x)
        r_e = (a1 / 2) * (a2 / 2) / np.hypot((a2 / 2) * np.cos(theta), (a1 / 2) * np.sin(theta))
        want = np.sqrt(np.mean((np.hypot(x, y) - r_e) ** 2))
        assert ellipse_rms_px(cx, cy, a1, a2, ang, pts) == pytest.approx(want, rel=1e-12)
