"""The compiled helpers of §3.3: the arc split (``kernels.ellipses.arc_points`` behind
``ellipse.split_arcs``) against the NumPy statement it replaced, on random blob contours:
one to three overlapping ellipses (merged markers), some with speckle; and the RMS
distance from an ellipse, both against ``tofpose.stages.ellipses.reference.ellipses``."""

from __future__ import annotations

import numpy as np
import pytest

from tests.tofpose.stages.ellipses.reference.test_ellipses import _random_contours
from tofpose.stages.ellipses.ellipse import split_arcs
from tofpose.stages.ellipses.reference import ellipses as reference


def _split_arcs_reference(contour, angle_deg=40.0, min_points=6, smooth_sigma=2.0):
    """``split_arcs`` with the reference's arc split (``reference.ellipses.arc_points``)."""
    n = len(contour)
    if n < 2 * min_points:
        return [contour] if n >= min_points else []
    index, starts = reference.arc_points(
        contour.astype(np.float64), angle_deg, min_points, smooth_sigma
    )
    return [contour[index[starts[a] : starts[a + 1]]] for a in range(len(starts) - 1)]


def test_arcs_equal_the_numpy_statement_on_random_contours():
    rng = np.random.default_rng(0)
    n_arcs = 0
    for contour in _random_contours(rng, 600):
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
    the reference's r_e(theta) = ra rb / sqrt((rb cos theta)^2 + (ra sin theta)^2), theta =
    atan2 (``reference.ellipses.ellipse_rms_px``)."""
    from tofpose.stages.ellipses.kernels.ellipses import ellipse_rms_px

    rng = np.random.default_rng(4)
    for _ in range(500):
        cx, cy = rng.uniform(0, 300, 2)
        a1, a2 = rng.uniform(2, 60, 2)
        ang = rng.uniform(0, 180)
        pts = np.column_stack([cx + rng.normal(0, 20, 40), cy + rng.normal(0, 20, 40)])
        pts[0] = (cx, cy)  # one at the centre: theta = atan2(0, 0) = 0
        want = reference.ellipse_rms_px(cx, cy, a1, a2, ang, pts)
        assert ellipse_rms_px(cx, cy, a1, a2, ang, pts) == pytest.approx(want, rel=1e-12)
