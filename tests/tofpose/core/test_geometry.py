import numpy as np
import pytest

from tofpose.core.geometry import (
    RigidTransform,
    euler_deg_from_rotation,
    quaternion_wxyz_from_rotation,
    rotation_angle_deg,
    rotation_from_euler_deg,
)


def _rx(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _ry(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def _rz(a):
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def test_euler_convention_is_rz_ry_rx():
    p, y, r = np.radians([10.0, -20.0, 30.0])
    R = rotation_from_euler_deg(10, -20, 30)
    np.testing.assert_allclose(R, _rz(r) @ _ry(y) @ _rx(p), atol=1e-12)
    np.testing.assert_allclose(euler_deg_from_rotation(R), [10, -20, 30], atol=1e-9)


def test_quaternion_has_nonnegative_w_and_matches_angle():
    R = rotation_from_euler_deg(0, 0, 200)
    q = quaternion_wxyz_from_rotation(R)
    assert q[0] >= 0
    assert 2 * np.degrees(np.arccos(q[0])) == pytest.approx(160.0)
    assert rotation_angle_deg(np.eye(3), R) == pytest.approx(160.0)


def test_transform_compose_inverse():
    a = RigidTransform.from_euler_deg(5, 10, -30, (1, 2, 3))
    b = RigidTransform.from_euler_deg(-40, 2, 7, (-5, 0, 9))
    x = np.array([[1.0, 2.0, 3.0], [-4.0, 0.5, 7.0]])
    np.testing.assert_allclose(a.compose(b).apply(x), a.apply(b.apply(x)))
    np.testing.assert_allclose(a.inverse().apply(a.apply(x)), x, atol=1e-12)
    np.testing.assert_allclose(a.as_matrix()[:3, 3], a.t_mm)


def test_facing_euler_reads_zero_face_on_and_never_flips():
    from tofpose.core.geometry import FACING, facing_euler_deg, rotation_from_euler_deg

    np.testing.assert_allclose(facing_euler_deg(FACING), [0, 0, 0], atol=1e-12)
    for angles in ([0.01, -0.02, 0.0], [-0.01, 0.02, 0.0], [3.0, -4.0, 10.0]):
        R = rotation_from_euler_deg(*angles) @ FACING  # tilted from facing
        np.testing.assert_allclose(facing_euler_deg(R), angles, atol=1e-9)


def test_closed_form_euler_and_quaternion_agree_with_scipy():
    """The closed forms (no scipy call per frame) give scipy's answers."""
    from scipy.spatial.transform import Rotation

    from tofpose.core.geometry import (
        euler_deg_from_rotation,
        quaternion_wxyz_from_rotation,
        rotation_from_euler_deg,
    )

    for R in Rotation.random(2000, random_state=3).as_matrix():
        ref = Rotation.from_matrix(R).as_euler("xyz", degrees=True)
        np.testing.assert_allclose(euler_deg_from_rotation(R), ref, atol=1e-9)
        x, y, z, w = Rotation.from_matrix(R).as_quat()
        q = np.array([w, x, y, z]) * (1 if w >= 0 else -1)
        np.testing.assert_allclose(quaternion_wxyz_from_rotation(R), q, atol=1e-12)
    # gimbal lock (yaw 90 deg): the angles still give back the rotation
    R = rotation_from_euler_deg(20.0, 90.0, 5.0)
    np.testing.assert_allclose(rotation_from_euler_deg(*euler_deg_from_rotation(R)), R, atol=1e-9)


@pytest.mark.parametrize("euler", [(10.0, 20.0, 5.0), (-30.0, 60.0, 170.0), (0.0, 0.0, 0.0)])
def test_facing_euler_sigmas_are_the_spread_of_the_angles_under_the_covariance(euler):
    """Monte Carlo: rotation vectors drawn from a covariance (left perturbation) move the
    facing Euler angles by the spread the function gives, to 3 %; the rotation vector's
    own sigmas are not that spread (yaw near 60 deg mixes the axes)."""
    from scipy.spatial.transform import Rotation

    from tofpose.core.geometry import facing_euler_deg, facing_euler_sigma_deg

    R = rotation_from_euler_deg(*euler) @ np.diag([1.0, -1.0, -1.0])
    np.testing.assert_allclose(facing_euler_deg(R), euler, atol=1e-9)
    A = np.array([[1.0, 0.3, 0.0], [0.3, 2.0, 0.1], [0.0, 0.1, 0.5]]) * 1e-4
    cov = np.zeros((6, 6))
    cov[:3, :3] = A
    got = facing_euler_sigma_deg(R, cov)
    rng = np.random.default_rng(0)
    w = rng.multivariate_normal(np.zeros(3), A, 20000)
    angles = np.array([facing_euler_deg(Rotation.from_rotvec(v).as_matrix() @ R) for v in w])
    spread = np.std((angles - euler + 180.0) % 360.0 - 180.0, axis=0)
    np.testing.assert_allclose(got, spread, rtol=0.03)
    if euler[1] == 60.0:
        assert np.abs(got - np.degrees(np.sqrt(np.diag(A)))).max() > 0.1
    assert np.all(np.isnan(facing_euler_sigma_deg(R, np.full((6, 6), np.nan))))
