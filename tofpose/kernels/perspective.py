"""Perspective bias of projected discs (§3.3's projected-circle bias), compiled; the
method is documented at ``tofpose.extraction.disc_image_centre_offsets_px``."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


@jit
def disc_centre_offsets(K, centres, normal, radii):
    """Image ellipse centre minus projected centre, (m, 2) px, of discs with centres
    (m, 3) mm in the camera frame, a shared unit-able normal (3,) and radii (m,) mm."""
    n = normal / np.sqrt((normal**2).sum())
    ref = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    a = np.cross(n, ref)
    a = a / np.sqrt((a**2).sum())
    b = np.cross(n, a)
    m = centres.shape[0]
    out = np.empty((m, 2))
    cols = np.empty((3, 3))
    for i in range(m):
        cols[:, 0] = a
        cols[:, 1] = b
        cols[:, 2] = centres[i]
        Hinv = np.linalg.inv(K @ cols)
        D = np.diag(np.array([1.0, 1.0, -(radii[i] ** 2)]))
        Q = Hinv.T @ D @ Hinv
        centre = -np.linalg.solve(Q[:2, :2].copy(), Q[:2, 2].copy())
        p = K @ centres[i]
        out[i, 0] = centre[0] - p[0] / p[2]
        out[i, 1] = centre[1] - p[1] / p[2]
    return out
