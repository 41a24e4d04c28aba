import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.sim.bench import R_FACING
from tofpose.stages.pixelfit.model import Discs, build_windows, disc_images
from tofpose.stages.pixelfit.reference.images import box_coverage


@pytest.mark.parametrize(
    ("s", "expected"), [(10.0, 1.0), (-10.0, 0.0), (0.0, 0.5), (0.125, 0.75), (-0.125, 0.25)]
)
def test_box_coverage_of_an_axis_aligned_edge(s, expected):
    # a square of half-side 0.25 cut by the line x = s: area fraction (s + 0.25) / 0.5
    got = box_coverage(np.array(s), np.array(0.25), np.array(1e-9))
    np.testing.assert_allclose(got, expected, atol=1e-6)


def test_box_coverage_of_a_diagonal_edge_is_the_triangle():
    # unit square (half-side 0.5), normal (1, 1)/sqrt2: the corner triangle below
    # x + y = -1 + c has area c^2 / 2
    g = np.sqrt(0.5)
    a = b = g * 0.5
    c = 0.3
    s = (-1.0 + c) * g  # signed distance of the line from the centre along g
    np.testing.assert_allclose(box_coverage(np.array(s), a, b), c**2 / 2, rtol=1e-12)


def test_coverage_sums_to_the_projected_disc_area():
    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(R_FACING, np.array([0.0, 0.0, 2000.0]))
    discs = Discs.from_catalog(cat, cat.ids)
    h, w = cam.shape
    win = build_windows(np.zeros((h, w)), np.zeros((h, w)), cam, discs, T.R, T.t_mm)
    images = disc_images(T.R, T.t_mm, discs, win, mm_per_radian=4000.0, reference_mm=2000.0)
    z = (T.apply(discs.centres_mm))[:, 2]
    area = np.pi * (discs.radii_mm * cam.fx / z) ** 2  # a facing disc near the axis
    np.testing.assert_allclose(images.coverage.sum(axis=1), area, rtol=3e-3)


def test_discs_name_a_missing_or_repeated_id():
    with pytest.raises(ValueError, match="not in the catalog"):
        Discs.from_catalog(paper_target(), [1, 2, 99])
    with pytest.raises(ValueError, match="twice"):
        Discs.from_catalog(paper_target(), [1, 1, 2])
