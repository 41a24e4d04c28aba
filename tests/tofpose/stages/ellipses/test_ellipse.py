import cv2
import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.ellipses.arithmetic import REFERENCE
from tofpose.stages.ellipses.ellipse import (
    blob_contour,
    cone_distance_mm,
    ellipse_residual_px,
    ellipses_from_arcs,
    fit_ellipse,
    outline_ellipse,
    split_arcs,
)


@pytest.mark.parametrize("tilt_deg", [0.0, 25.0, 50.0])
@pytest.mark.parametrize("offset_mm", [(0.0, 0.0), (400.0, -250.0)])
def test_cone_distance_eq24_equals_distance_to_circle_centre(tilt_deg, offset_mm):
    cam = CameraModel()
    R = rotation_from_euler_deg(180 + tilt_deg, 12, 0)
    c = np.array([*offset_mm, 2500.0])
    th = np.linspace(0, 2 * np.pi, 360, endpoint=False)
    pts = c + 40.0 * (np.outer(np.cos(th), R[:, 0]) + np.outer(np.sin(th), R[:, 1]))
    e = fit_ellipse(cam.project(pts))
    assert cone_distance_mm(e, cam.K, 40.0) == pytest.approx(np.linalg.norm(c), rel=1e-5)


def test_fit_ellipse_and_residual():
    th = np.linspace(0, 2 * np.pi, 100, endpoint=False)
    a, b, ang = 20.0, 8.0, np.radians(30)
    x = 50 + a * np.cos(th) * np.cos(ang) - b * np.sin(th) * np.sin(ang)
    y = 40 + a * np.cos(th) * np.sin(ang) + b * np.sin(th) * np.cos(ang)
    pts = np.column_stack((x, y))
    (cx, cy), axes, _ = e = fit_ellipse(pts)
    assert (cx, cy) == pytest.approx((50, 40), abs=1e-3)
    assert sorted(axes) == pytest.approx([16, 40], abs=1e-2)
    assert ellipse_residual_px(e, pts) < 1e-3
    assert ellipse_residual_px(e, pts + [1.0, 0.0]) > 0.3


def test_arcs_split_two_merged_discs_into_two_ellipses():
    """§3.3 supplement: two overlapping discs form one blob; arcs recover both."""
    mask = np.zeros((80, 120), np.uint8)
    cv2.circle(mask, (45, 40), 18, 1, -1)
    cv2.circle(mask, (75, 40), 18, 1, -1)
    arcs = split_arcs(blob_contour(mask))
    assert len(arcs) >= 2
    found = ellipses_from_arcs(arcs, d_min_px=20, d_max_px=50, max_residual_px=1.0)
    centres = sorted(e[0] for e, _ in found)
    assert len(centres) == 2
    np.testing.assert_allclose(centres[0], (45, 40), atol=1.0)
    np.testing.assert_allclose(centres[1], (75, 40), atol=1.0)


def test_contour_with_an_origin_is_the_contour_shifted():
    mask = np.zeros((12, 15), np.uint8)
    mask[3:9, 2:11] = 1
    mask[5, 12] = 1  # a smaller second region: the larger one is returned
    plain = blob_contour(mask)
    shifted = blob_contour(mask, (140, 61))
    assert shifted.dtype == np.float32 and len(plain) == 2 * (6 + 9) - 4
    np.testing.assert_array_equal(shifted, plain + [140, 61])


@pytest.mark.parametrize("arithmetic", ["compiled", "reference"])
def test_outline_ellipse_is_contour_fit_and_residual_in_one(arithmetic):
    """The per-candidate confirmation step gives exactly what blob_contour, fit_ellipse
    and ellipse_residual_px give one after the other (the same ellipse, the same RMS),
    in image coordinates, and None where they find no ellipse."""
    kw = {"arithmetic": REFERENCE} if arithmetic == "reference" else {}
    mask = np.zeros((40, 50), np.uint8)
    cv2.ellipse(mask, ((24.3, 19.6), (30.0, 17.0), 25.0), 1, -1)
    mask[2:5, 40:44] = 1  # a smaller second region: the larger outline is fitted
    origin = (301, 117)
    got = outline_ellipse(mask, origin, 10, **kw)
    pts = blob_contour(mask, origin)
    want = fit_ellipse(pts)
    assert got is not None and want is not None
    assert got[0] == want
    assert got[1] == ellipse_residual_px(want, pts, **kw)
    assert got[0][0] == pytest.approx((24.3 + 301, 19.6 + 117), abs=0.3)
    assert got[1] < 0.5
    assert outline_ellipse(mask, origin, len(pts) + 1, **kw) is None  # too few points
    tiny = np.zeros((5, 5), np.uint8)
    tiny[2, 1:3] = 1  # a 2-pixel outline: no ellipse
    assert outline_ellipse(tiny, (0, 0), 0, **kw) is None
    assert outline_ellipse(np.zeros((5, 5), np.uint8), (0, 0), 0, **kw) is None
