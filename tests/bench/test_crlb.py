"""The Cramer-Rao bound of ``bench/crlb.py`` against the covariance of an efficient
estimator: with measurements drawn from exactly the model the bound assumes (each
marker's image centre with the inverse of its 2 x 2 Fisher information, its range with
the combined sigma of its pixels), the maximum-likelihood pose's errors over many draws
have the bound's covariance (at this signal, ML is efficient). A sign or a block of the
Jacobian wrong, or an isotropic bearing sigma in place of the 2 x 2 information, moves
the ratio off 1."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from bench.crlb import bearing_information_px2, marker_jacobians, pose_crlb  # noqa: E402
from tofpose import CameraModel, paper_target  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import FIRST_DISC, TargetScene  # noqa: E402

DRAWS = 400


def _model(cam, cat, sensor, frame, T):
    """Per visible marker: catalog position, 2 x 2 information, range variance."""
    out = []
    for k, pos in enumerate(cat.positions_mm):
        m = (frame.surface_id == FIRST_DISC + k) & (frame.amplitude >= sensor.min_amplitude_counts)
        if not m.any():
            continue
        info = bearing_information_px2(frame, cam, T, pos, cat.diameters_mm[k] / 2, m)
        if info is None:
            continue
        a, b = frame.amplitude[m], frame.background[m]
        var_r = 1.0 / np.sum(1.0 / sensor.distance_sigma_mm(a, b) ** 2)
        out.append((pos, info, var_r))
    return out


def _predict(cam, markers, R, t):
    p = np.array([R @ pos + t for pos, _, _ in markers])
    return cam.project(p), np.linalg.norm(p, axis=1)


def test_the_bound_is_the_covariance_of_the_ml_pose_on_the_models_measurements():
    cam, cat, sensor = CameraModel(), paper_target(), SensorModel()
    T = RigidTransform(
        rotation_from_euler_deg(8, -12, 20) @ R_FACING, np.array([60.0, -40.0, 3000.0])
    )
    frame = render_frame(cam, TargetScene(), T, sensor, np.random.default_rng(3))
    markers = _model(cam, cat, sensor, frame, T)
    assert len(markers) >= 6
    bound_p, bound_a = pose_crlb(frame, T, cam, cat, sensor)
    uv0, rho0 = _predict(cam, markers, T.R, T.t_mm)
    chol = [np.linalg.cholesky(np.linalg.inv(info)) for _, info, _ in markers]
    whiten = [np.linalg.cholesky(info).T for _, info, _ in markers]
    sr = np.sqrt([v for _, _, v in markers])
    rng = np.random.default_rng(7)
    errors = []
    for _ in range(DRAWS):
        uv = uv0 + np.array([c @ rng.standard_normal(2) for c in chol])
        rho = rho0 + sr * rng.standard_normal(len(markers))

        def residuals(x, uv=uv, rho=rho):
            R = Rotation.from_rotvec(x[:3]).as_matrix() @ T.R
            uvp, rhop = _predict(cam, markers, R, T.t_mm + x[3:])
            r_uv = [w @ d for w, d in zip(whiten, uvp - uv, strict=True)]
            return np.concatenate([np.ravel(r_uv), (rhop - rho) / sr])

        errors.append(least_squares(residuals, np.zeros(6), x_scale=[1e-4] * 3 + [0.1] * 3).x)
    e = np.array(errors)
    rms_attitude_deg = np.degrees(np.sqrt(np.mean(np.sum(e[:, :3] ** 2, axis=1))))
    rms_position_mm = np.sqrt(np.mean(np.sum(e[:, 3:] ** 2, axis=1)))
    # 400 draws: the RMS of a 3-D error is known to ~4 % (1 sigma)
    assert 0.88 < rms_attitude_deg / bound_a < 1.12, (rms_attitude_deg, bound_a)
    assert 0.88 < rms_position_mm / bound_p < 1.12, (rms_position_mm, bound_p)


def test_the_pixel_jacobian_is_the_projections_derivative():
    """A small rotation and translation move the marker's pixel and range as the
    Jacobians say (to first order)."""
    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(rotation_from_euler_deg(5, 10, -30) @ R_FACING, np.array([0, 0, 2500.0]))
    pos = cat.positions_mm[2]
    J_uv, J_rho = marker_jacobians(cam, T, pos)
    d = np.array([2e-5, -1e-5, 3e-5, 0.05, -0.08, 0.1])
    R = Rotation.from_rotvec(d[:3]).as_matrix() @ T.R
    p0, p1 = T.R @ pos + T.t_mm, R @ pos + T.t_mm + d[3:]
    duv = cam.project(p1[None])[0] - cam.project(p0[None])[0]
    assert np.allclose(duv, J_uv @ d, rtol=1e-3, atol=1e-6)
    assert np.isclose(np.linalg.norm(p1) - np.linalg.norm(p0), J_rho @ d, rtol=1e-3)
