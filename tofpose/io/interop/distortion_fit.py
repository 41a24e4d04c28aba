"""A lens model with more coefficients than ``CameraModel`` holds, as the nearest
OpenCV (k1, k2, p1, p2, k3): what an imported camera with a rational lens model (Azure
Kinect's Brown-Conrady with k4..k6; ROS's ``rational_polynomial``) is stored as.

``CameraModel`` (and the pipeline's compiled projection) carries OpenCV's five
coefficients. A rational model ``(1 + k1 r^2 + k2 r^4 + k3 r^6) / (1 + k4 r^2 + k5 r^4 +
k6 r^6)`` is not one of them, so the five are fitted: least squares of the pixel
positions that the rational model (OpenCV's ``projectPoints`` with eight coefficients)
gives to a grid of rays over the field the device measures, the intrinsics kept. The
largest pixel error of the fit is returned with it, for the importer to state.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares

#: rays per axis of the fitting grid (over [-r, r] x [-r, r] of normalised coordinates)
GRID_RAYS = 101


@dataclass(frozen=True)
class DistortionFit:
    """The five coefficients fitted to a rational lens model.

    Attributes
    ----------
    dist : tuple of 5 floats
        OpenCV (k1, k2, p1, p2, k3).
    max_error_px, rms_error_px : float
        Largest and root-mean-square pixel distance between the two models over the
        fitted rays.
    field_radius : float
        The fit covered rays with ``hypot(x/z, y/z) <= field_radius`` that land inside
        the image.
    """

    dist: tuple[float, float, float, float, float]
    max_error_px: float
    rms_error_px: float
    field_radius: float


def fit_five_coefficients(
    K: np.ndarray,
    dist8: np.ndarray,
    *,
    width: int,
    height: int,
    field_radius: float,
) -> DistortionFit:
    """Fit OpenCV's (k1, k2, p1, p2, k3) to an eight-coefficient rational lens model.

    Parameters
    ----------
    K : ndarray of shape (3, 3)
        The intrinsic matrix (pixels), shared by both models.
    dist8 : ndarray of shape (8,)
        OpenCV's rational model (k1, k2, p1, p2, k3, k4, k5, k6).
    width, height : int, keyword-only
        The image size in pixels: rays that the rational model puts outside it are left
        out.
    field_radius : float, keyword-only
        The largest undistorted radius ``hypot(x/z, y/z)`` fitted: the device's field of
        view (beyond it, a polynomial cannot follow the rational model and would give up
        accuracy where the device measures).

    Returns
    -------
    DistortionFit
        ``ValueError`` when fewer than 20 rays of the field land in the image.
    """
    K = np.asarray(K, np.float64)
    dist8 = np.asarray(dist8, np.float64)
    if K.shape != (3, 3) or dist8.shape != (8,):
        raise ValueError(f"K must be (3, 3) and dist8 (8,), got {K.shape} and {dist8.shape}")
    if not field_radius > 0:
        raise ValueError(f"field_radius must be positive, got {field_radius}")
    axis = np.linspace(-field_radius, field_radius, GRID_RAYS)
    x, y = np.meshgrid(axis, axis)
    rays = np.column_stack((x.ravel(), y.ravel(), np.ones(x.size)))
    rays = rays[np.hypot(rays[:, 0], rays[:, 1]) <= field_radius]
    zero = np.zeros(3)
    target = cv2.projectPoints(rays, zero, zero, K, dist8)[0].reshape(-1, 2)
    inside = (
        (target[:, 0] >= -0.5)
        & (target[:, 0] <= width - 0.5)
        & (target[:, 1] >= -0.5)
        & (target[:, 1] <= height - 0.5)
    )
    rays, target = rays[inside], target[inside]
    if len(rays) < 20:
        raise ValueError(
            f"only {len(rays)} rays within radius {field_radius} land in the "
            f"{width} x {height} image: no lens fit"
        )

    def residuals(d5: np.ndarray) -> np.ndarray:
        return (cv2.projectPoints(rays, zero, zero, K, d5)[0].reshape(-1, 2) - target).ravel()

    rational = bool(dist8[5:].any())  # without k4..k6 the five are the model itself
    d5 = least_squares(residuals, np.zeros(5), method="lm").x if rational else dist8[:5]
    err = np.hypot(*residuals(d5).reshape(-1, 2).T)
    k1, k2, p1, p2, k3 = (float(v) for v in d5)
    return DistortionFit(
        dist=(k1, k2, p1, p2, k3),
        max_error_px=float(err.max()),
        rms_error_px=float(np.sqrt(np.mean(err**2))),
        field_radius=float(field_radius),
    )
