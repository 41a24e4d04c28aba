"""The camera model as the paper states it (§2.2, Eqs. 7-9) with OpenCV's lens model:
projection of camera-frame points to pixels and the unit line of sight of a pixel.

K : (3, 3) intrinsic matrix; dist : (5,) OpenCV's (k1, k2, p1, p2, k3). Pixels (u, v) are
(column, row) from the centre of the top-left pixel; the camera frame is OpenCV's (x
right, y down, z along the boresight; the paper's Eq. 7 has x left and y up).
"""

from __future__ import annotations

import cv2
import numpy as np


def project(points_mm, K, dist) -> np.ndarray:
    """Eq. 7 (with lens distortion): pixels (n, 2) of camera-frame points (n, 3) in front
    of the camera, by ``cv2.projectPoints``."""
    p = np.asarray(points_mm, float).reshape(-1, 3)
    uv, _ = cv2.projectPoints(
        p, np.zeros(3), np.zeros(3), np.asarray(K, float), np.asarray(dist, float)
    )
    return uv.reshape(-1, 2)


def normalized(uv_px, K, dist) -> np.ndarray:
    """Undistorted normalised coordinates (n, 2), Eq. 8's (tan phi, tan omega), of pixels
    (n, 2), by ``cv2.undistortPoints`` (its five fixed-point iterations)."""
    uv = np.asarray(uv_px, float).reshape(-1, 1, 2)
    return cv2.undistortPoints(uv, np.asarray(K, float), np.asarray(dist, float)).reshape(-1, 2)


def bearings(uv_px, K, dist) -> np.ndarray:
    """Eq. 9: unit lines of sight e = u / |u|, u = (tan phi, tan omega, 1), (n, 3)."""
    xy = normalized(uv_px, K, dist)
    u = np.column_stack((xy, np.ones(len(xy))))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def back_project(uv_px, distance_mm, K, dist) -> np.ndarray:
    """Eq. 8: the measured point y = rho e of a pixel and its radial distance rho, (n, 3)."""
    return bearings(uv_px, K, dist) * np.asarray(distance_mm, float).reshape(-1, 1)
