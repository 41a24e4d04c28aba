"""``ros2_covariance``: our (rotation vector rad, translation mm) covariance in ROS's
(x, y, z m, rotX, rotY, rotZ rad) order, element by element."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tofpose.io.interop.ros2_covariance import ros_covariance, ros_covariance_row_major


@pytest.mark.parametrize(
    ("ours", "ros", "scale"),
    [
        ((2, 2), (5, 5), 1.0),  # rotation about the boresight (our roll axis): rotZ
        ((0, 0), (3, 3), 1.0),  # about camera x (our pitch axis): rotX
        ((1, 1), (4, 4), 1.0),  # about camera y (our yaw axis): rotY
        ((3, 3), (0, 0), 1e-6),  # x, mm^2 -> m^2
        ((5, 5), (2, 2), 1e-6),  # z (along the boresight)
        ((5, 0), (2, 3), 1e-3),  # z with rotX, mm rad -> m rad
        ((1, 4), (4, 1), 1e-3),  # rotY with y
    ],
)
def test_each_element_lands_in_ross_place_in_ross_units(ours, ros, scale):
    C = np.zeros((6, 6))
    C[ours] = C[ours[::-1]] = 4.0
    out = ros_covariance(C)
    expected = np.zeros((6, 6))
    expected[ros] = expected[ros[::-1]] = 4.0 * scale
    np.testing.assert_array_equal(out, expected)


def test_a_full_covariance_is_a_congruence_and_stays_symmetric_positive():
    rng = np.random.default_rng(1)
    A = rng.normal(size=(6, 6))
    C = A @ A.T
    out = ros_covariance(C)
    P = np.zeros((6, 6))
    P[[0, 1, 2, 3, 4, 5], [3, 4, 5, 0, 1, 2]] = 1.0  # ROS row i takes our p_i
    S = np.diag([1e-3, 1e-3, 1e-3, 1.0, 1.0, 1.0])
    np.testing.assert_allclose(out, S @ P @ C @ P.T @ S, rtol=1e-15)
    np.testing.assert_array_equal(out, out.T)
    assert np.all(np.linalg.eigvalsh(out) > 0)
    assert ros_covariance_row_major(C) == out.ravel().tolist()


@pytest.mark.parametrize("shape", [(3, 3), (12, 12), (36,)])
def test_a_covariance_of_another_shape_is_refused_naming_it(shape):
    with pytest.raises(ValueError, match=re.escape(f"is (6, 6), got shape {shape}")):
        ros_covariance(np.zeros(shape))
