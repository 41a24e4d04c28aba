"""The oracle estimator: true correspondences and exact centroids, with the frame's own
range noise, solved by the same weighted SVD + maximum-likelihood refinement."""

from __future__ import annotations

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.render import RenderedFrame
from tofpose.sim.scene import FIRST_DISC
from tofpose.stages.pose.pose import refine_maximum_likelihood, weighted_absolute_orientation

BEARING_SIGMA_PX = 0.03  # the pipeline's centroid sigma floor
RANGE_SIGMA_FLOOR_MM = 1.0


def oracle_pose(
    frame: RenderedFrame, T_true: RigidTransform, camera: CameraModel, catalog: Catalog
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """(R, t_mm, covariance (6, 6)) or None when fewer than 3 discs are seen.

    Each visible disc's centre is projected exactly; its range is the true centre range
    plus the median distance error of the disc's valid pixels in this frame.
    """
    X = catalog.positions_mm
    Y = X @ T_true.R.T + T_true.t_mm
    sid = frame.surface_id.reshape(camera.height, camera.width)
    err = frame.distance_mm - frame.true_distance_mm
    keep, d_rho, sig = [], [], []
    for i in range(len(X)):
        pix = (sid == FIRST_DISC + i) & np.isfinite(err)
        n = int(pix.sum())
        if n == 0 or Y[i, 2] <= 0:
            continue
        e = err[pix]
        keep.append(i)
        d_rho.append(float(np.median(e)))
        sd = 1.2533 * float(np.std(e)) / np.sqrt(n) if n > 1 else 50.0
        sig.append(max(sd, RANGE_SIGMA_FLOOR_MM))
    if len(keep) < 3:
        return None
    keep = np.array(keep)
    uv = camera.project(Y[keep])
    e = camera.bearings(uv)
    rho = np.linalg.norm(Y[keep], axis=1) + np.array(d_rho)
    sig_rng = np.array(sig)
    sig_b = np.full(len(keep), BEARING_SIGMA_PX / camera.fx)
    w = 1.0 / (sig_rng**2 + (rho * sig_b) ** 2)
    R0, t0 = weighted_absolute_orientation(X[keep], e * rho[:, None], w)
    ml = refine_maximum_likelihood(X[keep], e, rho, R0, t0, sig_rng, sig_b)
    return ml.R, ml.t, ml.covariance
