"""Cramer-Rao lower bound of the pose from the measurement model (issue 13, item 6).

At the true pose, each visible marker contributes two bearing measurements and one range
(the ToF model of Eq. 10). Their variances come from the simulator's physics at that pose,
not from the pipeline: the range is the best combination of the marker's pixels, each of
sigma ``c / (4 pi f) sqrt(A + B) / (k A)`` (1 / sum of 1 / sigma^2); the bearing is the
intensity-weighted centroid (Eq. 19) of the expected signal with shot-noise variance
A + B per pixel, with the pixel-sampling term of the measurement model
(``tofpose.uncertainty.sampling_sigma_px``: a blob of 1-3 px locates its centre no better
than its pixels do) added in quadrature. The bound is (J^T J)^-1 over the six pose
parameters. It leaves out blur and edge mixing.
"""

from __future__ import annotations

import numpy as np

from tofpose.camera import CameraModel
from tofpose.catalog import Catalog
from tofpose.geometry import RigidTransform
from tofpose.pose import measurement_jacobian
from tofpose.sim.render import RenderedFrame, SensorModel
from tofpose.sim.scene import FIRST_DISC
from tofpose.uncertainty import sampling_sigma_px


def pose_crlb(
    f: RenderedFrame, T: RigidTransform, cam: CameraModel, cat: Catalog, sensor: SensorModel
) -> tuple[float, float]:
    """(position bound mm, attitude bound deg): sqrt of the traces of the bound's blocks;
    NaN when fewer than three markers are visible."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width].astype(float)
    x, e, rho, s_r, s_b = [], [], [], [], []
    for k, pos in enumerate(cat.positions_mm):
        m = (f.surface_id == FIRST_DISC + k) & (f.amplitude >= sensor.min_amplitude_counts)
        if not m.any():
            continue
        a, b = f.amplitude[m], f.background[m]
        s_r.append(1.0 / np.sqrt(np.sum(1.0 / sensor.distance_sigma_mm(a, b) ** 2)))
        uu, vv, w = u[m], v[m], a.sum()
        cu, cv = (a * uu).sum() / w, (a * vv).sum() / w
        var = (((uu - cu) ** 2 + (vv - cv) ** 2) * (a + b)).sum() / w**2 / 2.0
        var += float(sampling_sigma_px(np.array([m.sum()]))[0]) ** 2
        s_b.append(np.sqrt(var) / cam.fx)
        p = T.R @ pos + T.t_mm
        x.append(pos)
        rho.append(np.linalg.norm(p))
        e.append(p / np.linalg.norm(p))
    if len(x) < 3:
        return float("nan"), float("nan")
    _, J = measurement_jacobian(np.array(x), np.array(e), np.array(rho), T.R, T.t_mm,
                                np.array(s_r), np.array(s_b))  # fmt: skip
    cov = np.linalg.inv(J.T @ J)
    return float(np.sqrt(np.trace(cov[3:, 3:]))), float(np.degrees(np.sqrt(np.trace(cov[:3, :3]))))
