"""The camera model's projection and lines of sight (``tofpose.core.camera.CameraModel``) for
the compiled kernels: the pinhole model, and with lens distortion OpenCV's 5-coefficient
model (k1, k2, p1, p2, k3) with the arithmetic of ``cv2.projectPoints`` and of
``cv2.undistortPoints`` (five fixed-point iterations, its default), so that a kernel
sees the same pixels and bearings as the Python stages."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit


@jit
def has_distortion(dist):
    """Whether any of the distortion coefficients (5,) is non-zero."""
    return np.any(dist != 0.0)


@jit
def project(points, fx, fy, cx, cy, dist):
    """Pixels (n, 2) of camera-frame points (n, 3) in front of the camera."""
    uv = np.empty((points.shape[0], 2))
    if not has_distortion(dist):
        for i in range(points.shape[0]):
            uv[i, 0] = fx * points[i, 0] / points[i, 2] + cx
            uv[i, 1] = fy * points[i, 1] / points[i, 2] + cy
        return uv
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    for i in range(points.shape[0]):
        X, Y, Z = points[i, 0], points[i, 1], points[i, 2]
        z = 1.0 / Z
        x, y = X * z, Y * z
        r2 = x * x + y * y
        r4 = r2 * r2
        r6 = r4 * r2
        cdist = 1 + k1 * r2 + k2 * r4 + k3 * r6
        a1 = 2 * x * y
        a2 = r2 + 2 * x * x
        a3 = r2 + 2 * y * y
        xd = x * cdist + p1 * a1 + p2 * a2
        yd = y * cdist + p1 * a3 + p2 * a1
        uv[i, 0] = xd * fx + cx
        uv[i, 1] = yd * fy + cy
    return uv


@jit
def bearings(uv, fx, fy, cx, cy, dist):
    """Unit lines of sight (n, 3) (Eq. 9) of pixels (n, 2): ``CameraModel.bearings``."""
    n = uv.shape[0]
    e = np.empty((n, 3))
    distorted = has_distortion(dist)
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    ifx, ify = 1.0 / fx, 1.0 / fy
    for i in range(n):
        if not distorted:
            x = (uv[i, 0] - cx) / fx
            y = (uv[i, 1] - cy) / fy
        else:
            x0 = x = (uv[i, 0] - cx) * ifx
            y0 = y = (uv[i, 1] - cy) * ify
            for _ in range(5):
                r2 = x * x + y * y
                icdist = 1.0 / (1 + ((k3 * r2 + k2) * r2 + k1) * r2)
                if icdist < 0:
                    x, y = (uv[i, 0] - cx) * ifx, (uv[i, 1] - cy) * ify
                    break
                delta_x = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
                delta_y = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
                x = (x0 - delta_x) * icdist
                y = (y0 - delta_y) * icdist
        norm = np.sqrt(x * x + (y * y + 1.0))  # NumPy's order of the 3-term sum
        e[i, 0], e[i, 1], e[i, 2] = x / norm, y / norm, 1.0 / norm
    return e
