"""How a reported pose is judged against truth: its error, its Mahalanobis distance
against the reported covariance, and the success / wrong / confidently-wrong rules.

One set of rules for every accuracy figure the project prints (``bench/foreign.py``,
``bench/physics.py``, ``tofpose study``), so that a "success" means the same thing in a
Monte-Carlo study as in a table of frames from another renderer.

Conventions (those of ``tofpose.calibration.covariance.pose_nees`` and ``PoseResult``):

* pose error ``e`` (6,) = (rotation vector of ``R_est R_true^T`` in rad, ``t_est -
  t_true`` in mm): the pipeline's left perturbation, in the camera frame, in the order of
  the reported covariance (rotation vector rad, then translation mm);
* attitude error (deg) = the geodesic angle |e[:3]|; position error (mm) = |e[3:]|;
* squared Mahalanobis distance ``d2 = e^T Sigma^-1 e`` (mean 6 for a consistent
  covariance; "NEES/6" is its mean divided by 6, so 1 means consistent);
* a pose is "beyond 3 sigma" when ``d2`` exceeds the chi-square(6) quantile at the
  probability of a two-sided 3-sigma interval of one normal variable,
  p = erf(3 / sqrt 2) = 0.9973: ``CHI2_6_3SIGMA`` = 20.06. A consistent covariance puts
  0.27 % of poses beyond it.

Rules (position tolerance ``tol = max(20 mm, 0.5 % of the true range)``):

* success: a pose (ok) with attitude error <= 1 deg and position error <= tol;
* wrong: ok and (attitude error > 2 deg or position error > 2.5 tol);
* confidently wrong: wrong and beyond 3 sigma.

A frame without a pose counts against success, never as wrong.
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation
from scipy.stats import chi2

#: probability of a two-sided 3-sigma interval of one normal variable, erf(3 / sqrt 2)
P_3SIGMA = math.erf(3.0 / math.sqrt(2.0))
#: chi-square(6) quantile at P_3SIGMA (20.06): a pose's d2 beyond it is "beyond 3 sigma"
CHI2_6_3SIGMA = float(chi2.ppf(P_3SIGMA, 6))

SUCCESS_ATTITUDE_DEG = 1.0
POSITION_TOLERANCE_FLOOR_MM = 20.0
POSITION_TOLERANCE_FRACTION = 0.005  # of the true range
WRONG_ATTITUDE_DEG = 2.0
WRONG_POSITION_FACTOR = 2.5  # times the position tolerance

#: the pose error's components, in the order of ``pose_error`` and the covariance
AXES = ("rx", "ry", "rz", "x", "y", "z")


def position_tolerance_mm(range_mm):
    """max(20 mm, 0.5 % of the true range), elementwise; same shape as ``range_mm``."""
    r = np.asarray(range_mm, float)
    return np.maximum(POSITION_TOLERANCE_FLOOR_MM, POSITION_TOLERANCE_FRACTION * r)


def pose_error(R_est, t_est_mm, R_true, t_true_mm) -> np.ndarray:
    """(6,): rotation vector of ``R_est R_true^T`` (rad), then ``t_est - t_true`` (mm).
    R_* (3, 3) R_camera_target, t_* (3,) mm."""
    rot = Rotation.from_matrix(np.asarray(R_est) @ np.asarray(R_true).T).as_rotvec()
    return np.concatenate([rot, np.asarray(t_est_mm, float) - np.asarray(t_true_mm, float)])


def mahalanobis2(error: np.ndarray, covariance: np.ndarray) -> float:
    """Squared Mahalanobis distance e^T Sigma^-1 e of a pose error (6,) against its
    covariance (6, 6); inf when the covariance is singular."""
    try:
        return float(error @ np.linalg.solve(covariance, error))
    except np.linalg.LinAlgError:
        return math.inf


def judge(ok, attitude_error_deg, position_error_mm, d2, range_mm) -> dict[str, np.ndarray]:
    """The rules above over N frames (every argument (N,); errors and d2 NaN without a
    pose, d2 NaN without a covariance, which counts as beyond 3 sigma): bool arrays
    ``success``, ``wrong``, ``beyond_3sigma``, ``confidently_wrong``, each (N,)."""
    ok = np.asarray(ok, bool)
    att = np.asarray(attitude_error_deg, float)
    pos = np.asarray(position_error_mm, float)
    tol = position_tolerance_mm(range_mm)
    with np.errstate(invalid="ignore"):
        success = ok & (att <= SUCCESS_ATTITUDE_DEG) & (pos <= tol)
        wrong = ok & ((att > WRONG_ATTITUDE_DEG) | (pos > WRONG_POSITION_FACTOR * tol))
        beyond = ok & ~(np.asarray(d2, float) <= CHI2_6_3SIGMA)
    return {
        "success": success,
        "wrong": wrong,
        "beyond_3sigma": beyond,
        "confidently_wrong": wrong & beyond,
    }
