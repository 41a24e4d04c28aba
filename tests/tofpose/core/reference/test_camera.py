"""The reference camera model (Eqs. 7-9) against known truth."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.reference import camera as reference

K = np.array([[325.0, 0, 159.5], [0, 325.0, 119.5], [0, 0, 1]])
LENS = np.array([-0.21, 0.08, 0.0012, -0.0007, -0.01])


def test_a_pinhole_projects_by_similar_triangles_and_back_projects_to_the_point():
    p = np.array([[100.0, -50.0, 2000.0], [0.0, 0.0, 500.0]])
    uv = reference.project(p, K, np.zeros(5))
    np.testing.assert_allclose(uv, [[159.5 + 16.25, 119.5 - 8.125], [159.5, 119.5]], atol=1e-12)
    rho = np.linalg.norm(p, axis=1)
    np.testing.assert_allclose(reference.back_project(uv, rho, K, np.zeros(5)), p, atol=1e-9)


@pytest.mark.parametrize("dist", [np.zeros(5), LENS])
def test_bearings_are_unit_lines_of_sight_through_the_projected_points(dist):
    rng = np.random.default_rng(4)
    p = np.column_stack(
        (rng.uniform(-500, 500, 50), rng.uniform(-400, 400, 50), rng.uniform(1000, 6000, 50))
    )
    e = reference.bearings(reference.project(p, K, dist), K, dist)
    np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-14)
    # undistortPoints' five fixed-point iterations leave ~1e-6 of this lens's distortion
    np.testing.assert_allclose(
        e, p / np.linalg.norm(p, axis=1, keepdims=True), atol=1e-12 if not dist.any() else 2e-5
    )
