"""Cramer-Rao lower bound of the pose from the measurement model (issue 13, item 6).

At the true pose, each visible marker contributes two bearing measurements and one range
(the ToF model of Eq. 10). Their variances come from the simulator's physics at that pose
alone, not from the pipeline or any estimator: the range is the best combination of the
marker's pixels, each of sigma ``c / (4 pi f) sqrt(A + B) / (k A)`` (1 / sum of
1 / sigma^2); the bearing's information is that of the pixel-integrated image of the
disc: moving the disc's centre by du changes pixel p's expected amplitude by
``A_disc * dc_p / du``, where ``dc_p / du`` is the integral of the rim's outward normal
over the part of the rim inside pixel p (a uniform disc's coverage changes only at its
rim), with shot-noise variance ``A_p + B_p``. Fisher information ``sum_p (A_disc dc_p /
du)^2 / (A_p + B_p)``, a 2 x 2 information matrix I_k over the image axes (u, v) of the
disc's centre. The pose's Fisher information is, over the visible markers k,

    F = sum_k  J_uv,k^T I_k J_uv,k  +  J_rho,k^T J_rho,k / sigma_rho,k^2

with J the derivatives of the marker centre's pixel and range with respect to the pose
(a small rotation, rad, left-multiplied, then the translation, mm: the errors the
benches report), and the bound is F^-1. The whole 2 x 2 I_k enters: an isotropic
bearing sigma from its larger diagonal term would overstate the bound (it is then no
lower bound); one from 1 / lambda_max(I_k) would understate it. It leaves out blur (the
default sensor has none) and the surround's share of mixed pixels.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.render import RenderedFrame, SensorModel
from tofpose.sim.scene import FIRST_DISC

#: rim samples per disc for the coverage gradient
RIM_SAMPLES = 2048


def pose_crlb(
    f: RenderedFrame, T: RigidTransform, cam: CameraModel, cat: Catalog, sensor: SensorModel
) -> tuple[float, float]:
    """(position bound mm, attitude bound deg): sqrt of the traces of the bound's blocks;
    NaN when fewer than three markers are visible."""
    F = np.zeros((6, 6))
    visible = 0
    radii_mm = cat.diameters_mm / 2
    for k, pos in enumerate(cat.positions_mm):
        m = (f.surface_id == FIRST_DISC + k) & (f.amplitude >= sensor.min_amplitude_counts)
        if not m.any():
            continue
        info_uv = bearing_information_px2(f, cam, T, pos, radii_mm[k], m)
        if info_uv is None:
            continue
        a, b = f.amplitude[m], f.background[m]
        var_range_mm2 = 1.0 / np.sum(1.0 / sensor.distance_sigma_mm(a, b) ** 2)
        J_uv, J_rho = marker_jacobians(cam, T, pos)
        F += J_uv.T @ info_uv @ J_uv + np.outer(J_rho, J_rho) / var_range_mm2
        visible += 1
    if visible < 3:
        return float("nan"), float("nan")
    cov = np.linalg.inv(F)
    return float(np.sqrt(np.trace(cov[3:, 3:]))), float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))


#: finite-difference step of the projection's derivative, mm in the camera frame
PROJECTION_STEP_MM = 1e-3


def marker_jacobians(
    cam: CameraModel, T: RigidTransform, pos_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Derivatives of a marker centre's pixel (2, 6) and range (6,) with respect to the
    pose: a small rotation omega (rad) left-multiplied (``R' = exp([omega]) R``), then the
    translation (mm). The projection's derivative (lens distortion included) is a central
    difference of ``CameraModel.project``."""
    rx = T.R @ np.asarray(pos_mm, float)
    p = rx + T.t_mm
    dp_dpose = np.hstack([-_cross_matrix(rx), np.eye(3)])  # (3, 6)
    h = PROJECTION_STEP_MM
    steps = np.vstack([p + h * np.eye(3), p - h * np.eye(3)])
    uv = cam.project(steps)
    duv_dp = ((uv[:3] - uv[3:]) / (2 * h)).T  # (2, 3)
    return duv_dp @ dp_dpose, (p / np.linalg.norm(p)) @ dp_dpose


def _cross_matrix(v: np.ndarray) -> np.ndarray:
    """[v]_x (3, 3): [v]_x w = v x w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def bearing_information_px2(
    f: RenderedFrame,
    cam: CameraModel,
    T: RigidTransform,
    pos_mm,
    radius_mm: float,
    covered: np.ndarray,
) -> np.ndarray | None:
    """Fisher information (2, 2), px^-2, of the disc's image centre (u, v) (module
    docstring); None when the image carries none (the disc edge-on or out of the
    image). The rim is the projected circle of the disc
    (centre ``pos_mm`` in the target frame, normal the target's z axis); ``covered`` (H,
    W) marks the pixels the disc covers at their centre; with the pixels its rim crosses,
    their summed amplitude over the disc's image area is its amplitude per px^2."""
    theta = np.linspace(0.0, 2 * np.pi, RIM_SAMPLES, endpoint=False)
    rim_target = pos_mm + radius_mm * np.column_stack(
        [np.cos(theta), np.sin(theta), np.zeros_like(theta)]
    )
    rim = cam.project(rim_target @ T.R.T + T.t_mm)  # (N, 2) px
    seg = np.roll(rim, -1, axis=0) - rim  # rim element vectors
    normal = np.column_stack([seg[:, 1], -seg[:, 0]])  # outward for a counter-clockwise rim
    centre = rim.mean(axis=0)
    if np.sum(normal * (rim - centre)) < 0:
        normal = -normal
    col = np.rint(rim[:, 0]).astype(int)
    row = np.rint(rim[:, 1]).astype(int)
    inside = (col >= 0) & (col < cam.width) & (row >= 0) & (row < cam.height)
    col, row, normal = col[inside], row[inside], normal[inside]  # the image's part of it
    grad = np.zeros((cam.height, cam.width, 2))
    np.add.at(grad, (row, col), normal)  # d coverage / d (u, v) of each pixel
    touched = covered.copy()
    touched[row, col] = True
    area_px = 0.5 * abs(
        np.sum(rim[:, 0] * np.roll(rim[:, 1], -1) - np.roll(rim[:, 0], -1) * rim[:, 1])
    )
    # the disc's amplitude per unit of covered area: its pixels' sum over its area (the
    # plate's share counted as the disc's, which can only lower the bound)
    a_disc = float(f.amplitude[touched].sum()) / max(area_px, 1e-9)
    var_pixel = np.maximum(f.amplitude + f.background, 1.0)
    info = np.einsum("hwi,hwj->ij", grad, grad / var_pixel[..., None]) * a_disc**2
    if not np.all(np.isfinite(info)) or np.linalg.det(info) <= 1e-12 * np.trace(info) ** 2:
        return None  # no bearing information (the disc edge-on, or out of the image)
    return info
