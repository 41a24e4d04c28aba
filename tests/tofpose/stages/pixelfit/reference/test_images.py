"""The exact area of a straight rim over a sub-cell (``reference.images.box_coverage``)
against areas worked by hand."""

import numpy as np
import pytest

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
