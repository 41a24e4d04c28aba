"""Bench calibration: the camera's installation on the turntable and the target's placement
in the lab, from measured poses at known axis positions (beyond the paper, which names
both as its main error source, §6.4-6.5).

With ``A_i = T_lab_inner(encoders_i)`` (tofpose.lab.kinematics), the unknown mount
``X = T_inner_camera`` and placement ``Y = T_lab_target``, each measured pose is

    M_i = T_camera_target_i = X^-1 . A_i^-1 . Y            (A_i X M_i = Y)

a robot-world / hand-eye problem. The fit starts from the nominal mount and placement
(and, where the OpenCV build has it, also from ``calibrateRobotWorldHandEye``'s closed
form with camera = camera, world = target, gripper = inner axis, base = lab; the better
start wins); a weighted least-squares fit of all 12 parameters (scipy) refines it, each residual
divided by the measurement's 1-sigma (position mm, attitude rad). The parameter
covariance is ``(J^T J)^-1`` scaled by ``max(1, chi^2 / dof)``, so that an inconsistent
fit reports an honest uncertainty.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from tofpose.core.geometry import RigidTransform
from tofpose.lab.kinematics import axes_transform, camera_target

MIN_OBSERVATIONS = 3


@dataclass(frozen=True)
class BenchObservation:
    """One measured pose at known axis positions.

    positions : {"yaw", "pitch", "roll" (deg), "rail" (mm)} read back by the encoders.
    T_camera_target : the measured pose (e.g. the mean over a set-point's frames).
    sigma_mm, sigma_deg : 1-sigma of the measured position (per axis) and attitude.
    """

    positions: dict[str, float]
    T_camera_target: RigidTransform
    sigma_mm: float = 1.0
    sigma_deg: float = 0.05


@dataclass(frozen=True)
class BenchCalibration:
    """The estimated mount and placement with their uncertainty and the fit's residuals.

    sigmas : 1-sigma of (mount rotation xyz deg, mount translation xyz mm, placement
        rotation xyz deg, placement translation xyz mm), shape (12,); rotations as small
        rotation vectors about the estimate's own axes.
    residual_mm, residual_deg : per observation, shape (N,): position and geodesic
        attitude differences between measured and predicted poses.
    """

    T_inner_camera: RigidTransform
    T_lab_target: RigidTransform
    covariance: np.ndarray
    sigmas: np.ndarray
    residual_mm: np.ndarray
    residual_deg: np.ndarray
    chi2_per_dof: float
    initial: str  # "opencv" or "nominal": where the refinement started


def _rotvec_deg(R: np.ndarray) -> np.ndarray:
    return Rotation.from_matrix(R).as_rotvec(degrees=True)


def _perturb(T: RigidTransform, p: np.ndarray) -> RigidTransform:
    """T with a small rotation vector p[:3] (rad, body frame) and translation p[3:] (mm)."""
    return RigidTransform(T.R @ Rotation.from_rotvec(p[:3]).as_matrix(), T.t_mm + p[3:])


def _residuals(p, X0, Y0, obs) -> np.ndarray:
    X, Y = _perturb(X0, p[:6]), _perturb(Y0, p[6:])
    out = []
    for o in obs:
        P = camera_target(o.positions, X, Y)
        dt = (P.t_mm - o.T_camera_target.t_mm) / o.sigma_mm
        dr = Rotation.from_matrix(P.R.T @ o.T_camera_target.R).as_rotvec()
        out.append(np.r_[dt, dr / np.radians(o.sigma_deg)])
    return np.concatenate(out)


def _opencv_start(obs) -> tuple[RigidTransform, RigidTransform] | None:
    """Closed-form (X, Y) from OpenCV's robot-world hand-eye solver, or None when this
    OpenCV build lacks it (the 5.0 wheels do) or it fails."""
    solver = getattr(cv2, "calibrateRobotWorldHandEye", None)
    if solver is None:
        return None
    R_w2c = [o.T_camera_target.R for o in obs]
    t_w2c = [o.T_camera_target.t_mm.reshape(3, 1) for o in obs]
    inv = [axes_transform(o.positions).inverse() for o in obs]
    try:
        R_b2w, t_b2w, R_g2c, t_g2c = solver(
            R_w2c, t_w2c, [T.R for T in inv], [T.t_mm.reshape(3, 1) for T in inv]
        )
    except cv2.error:
        return None
    if not (np.all(np.isfinite(R_b2w)) and np.all(np.isfinite(R_g2c))):
        return None
    Y = RigidTransform(R_b2w, t_b2w.ravel()).inverse()  # base2world = T_target_lab
    X = RigidTransform(R_g2c, t_g2c.ravel()).inverse()  # gripper2cam = T_camera_inner
    return X, Y


def calibrate_bench(
    observations: Sequence[BenchObservation],
    nominal_inner_camera: RigidTransform,
    nominal_lab_target: RigidTransform,
) -> BenchCalibration:
    """Estimate ``T_inner_camera`` and ``T_lab_target`` (see the module docstring).

    Raises ``ValueError`` naming the problem for fewer than ``MIN_OBSERVATIONS``
    observations or observations without any rotation (the mount is then unobservable).
    """
    obs = list(observations)
    if len(obs) < MIN_OBSERVATIONS:
        raise ValueError(
            f"a bench calibration needs at least {MIN_OBSERVATIONS} observations, got {len(obs)}"
        )
    rots = np.array([_rotvec_deg(axes_transform(o.positions).R) for o in obs])
    if np.linalg.matrix_rank(rots - rots.mean(axis=0), tol=0.5) < 2:
        raise ValueError(
            "the observations rotate the turntable about fewer than two axes: the camera "
            "mount is not observable (use the 'calibration' campaign generator)"
        )
    starts = [("nominal", nominal_inner_camera, nominal_lab_target)]
    if (cv := _opencv_start(obs)) is not None:
        starts.append(("opencv", *cv))
    fits = [
        (least_squares(_residuals, np.zeros(12), args=(X0, Y0, obs), method="lm"), label, X0, Y0)
        for label, X0, Y0 in starts
    ]
    fit, label, X0, Y0 = min(fits, key=lambda f: f[0].cost)  # the first of equal costs
    X, Y = _perturb(X0, fit.x[:6]), _perturb(Y0, fit.x[6:])
    dof = max(fit.fun.size - 12, 1)
    chi2 = float(fit.fun @ fit.fun) / dof
    cov = np.linalg.pinv(fit.jac.T @ fit.jac) * max(1.0, chi2)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    sigmas = np.r_[np.degrees(sd[:3]), sd[3:6], np.degrees(sd[6:9]), sd[9:]]
    res_mm, res_deg = [], []
    for o in obs:
        P = camera_target(o.positions, X, Y)
        res_mm.append(float(np.linalg.norm(P.t_mm - o.T_camera_target.t_mm)))
        res_deg.append(float(np.linalg.norm(_rotvec_deg(P.R.T @ o.T_camera_target.R))))
    return BenchCalibration(X, Y, cov, sigmas, np.array(res_mm), np.array(res_deg), chi2, label)


def mean_pose(poses: Sequence[RigidTransform]) -> RigidTransform:
    """Mean of several poses: arithmetic mean translation, chordal mean rotation."""
    R = Rotation.from_matrix(np.array([p.R for p in poses])).mean().as_matrix()
    return RigidTransform(R, np.mean([p.t_mm for p in poses], axis=0))
