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
du)^2 / (A_p + B_p)`` per image axis, the inverse is the bearing's variance. The bound is
(J^T J)^-1 over the six pose parameters. It leaves out blur (the default sensor has
none) and the surround's share of mixed pixels.
"""

from __future__ import annotations

import math

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.render import RenderedFrame, SensorModel
from tofpose.sim.scene import FIRST_DISC
from tofpose.stages.pose.pose import measurement_jacobian

#: rim samples per disc for the coverage gradient
RIM_SAMPLES = 2048


def pose_crlb(
    f: RenderedFrame, T: RigidTransform, cam: CameraModel, cat: Catalog, sensor: SensorModel
) -> tuple[float, float]:
    """(position bound mm, attitude bound deg): sqrt of the traces of the bound's blocks;
    NaN when fewer than three markers are visible."""
    x, e, rho, s_r, s_b = [], [], [], [], []
    radii_mm = cat.diameters_mm / 2
    for k, pos in enumerate(cat.positions_mm):
        m = (f.surface_id == FIRST_DISC + k) & (f.amplitude >= sensor.min_amplitude_counts)
        if not m.any():
            continue
        a, b = f.amplitude[m], f.background[m]
        var_px2 = bearing_variance_px2(f, cam, T, pos, radii_mm[k], m)
        if not math.isfinite(var_px2):
            continue
        s_r.append(1.0 / np.sqrt(np.sum(1.0 / sensor.distance_sigma_mm(a, b) ** 2)))
        s_b.append(np.sqrt(var_px2) / cam.fx)
        p = T.R @ pos + T.t_mm
        x.append(pos)
        rho.append(np.linalg.norm(p))
        e.append(p / np.linalg.norm(p))
    if len(x) < 3:
        return float("nan"), float("nan")
    _, J = measurement_jacobian(
        np.array(x), np.array(e), np.array(rho), T.R, T.t_mm, np.array(s_r), np.array(s_b)
    )
    cov = np.linalg.inv(J.T @ J)
    return float(np.sqrt(np.trace(cov[3:, 3:]))), float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))


def bearing_variance_px2(
    f: RenderedFrame,
    cam: CameraModel,
    T: RigidTransform,
    pos_mm,
    radius_mm: float,
    covered: np.ndarray,
) -> float:
    """Lower bound (px^2, per image axis, the larger of the two) of the variance of the
    disc's image centre (module docstring). The rim is the projected circle of the disc
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
        return math.inf  # no bearing information (the disc edge-on, or out of the image)
    return float(np.max(np.diag(np.linalg.inv(info))))
