"""A device's distance image to the pipeline's and back: radial distance <-> z depth, and
raw distance codes (units, invalid codes) <-> float mm with NaN where invalid.

The pipeline measures the radial distance along each pixel's ray (Eq. 8's rho; what a
CW-ToF camera such as the EPC660 reads). Azure Kinect and ROS depth images give the z
depth instead: the coordinate along the boresight of the point the pixel sees. A point
``y = rho * e`` on the pixel's unit bearing ``e`` (the undistorted ray,
``CameraModel.pixel_bearings``) has ``z = rho * e_z``, so per pixel

    rho = z / e_z,        z = rho * e_z.

At the centre of the paper's camera e_z = 1; in its corners (26 deg and 20 deg off
axis) e_z = 0.85: a z image read as radial puts a corner 15 % too near. Which kind a
camera's frames are is ``CameraModel.distance_kind``; its raw codes are described by
``depth_unit_mm``, ``depth_invalid_code`` and ``depth_max_valid_code``.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.camera import CameraModel


def _checked(image: np.ndarray, camera: CameraModel, what: str) -> np.ndarray:
    """``image`` as an array of shape (..., H, W) of numbers; ``ValueError`` naming
    ``what`` otherwise."""
    image = np.asarray(image)
    if image.shape[-2:] != camera.shape:
        raise ValueError(
            f"{what} has shape {image.shape}, camera expects {camera.shape} (or a stack of them)"
        )
    if image.dtype.kind not in "iuf":
        raise ValueError(f"{what} must be numbers, got dtype {image.dtype}")
    return image


def _ray_z(camera: CameraModel) -> np.ndarray:
    """e_z of every pixel's unit bearing through the undistorted ray, shape (H, W)."""
    return camera.pixel_bearings()[:, :, 2]


def radial_from_z(z_mm: np.ndarray, camera: CameraModel) -> np.ndarray:
    """Radial distance along each pixel's ray from a z-depth image.

    Parameters
    ----------
    z_mm : ndarray of shape (H, W), or a stack (..., H, W)
        Depth along the boresight, mm; NaN where invalid (kept NaN).
    camera : CameraModel
        The camera whose pixels' rays (with its lens distortion) the image is on.

    Returns
    -------
    ndarray of ``z_mm``'s shape, float32
        ``rho = z / e_z`` per pixel, mm.
    """
    z = _checked(z_mm, camera, "z-depth image").astype(np.float64)
    return (z / _ray_z(camera)).astype(np.float32)


def z_from_radial(distance_mm: np.ndarray, camera: CameraModel) -> np.ndarray:
    """z depth of each pixel from a radial distance image (``radial_from_z``'s inverse).

    Parameters
    ----------
    distance_mm : ndarray of shape (H, W), or a stack (..., H, W)
        Radial distance along each pixel's ray, mm; NaN where invalid (kept NaN).
    camera : CameraModel

    Returns
    -------
    ndarray of ``distance_mm``'s shape, float32
        ``z = rho * e_z`` per pixel, mm.
    """
    rho = _checked(distance_mm, camera, "distance image").astype(np.float64)
    return (rho * _ray_z(camera)).astype(np.float32)


def decode_depth(raw: np.ndarray, camera: CameraModel) -> np.ndarray:
    """The pipeline's distance image from a device's raw distance image.

    Codes equal to ``camera.depth_invalid_code``, above ``camera.depth_max_valid_code``
    or not finite become NaN; the rest are scaled by ``camera.depth_unit_mm`` and, for
    a z-depth camera (``distance_kind == "z"``), converted to radial distance.

    Parameters
    ----------
    raw : ndarray of shape (H, W)
        The device's codes (e.g. uint16 mm) or float depths in ``depth_unit_mm`` units.
    camera : CameraModel

    Returns
    -------
    ndarray of shape (H, W), float32
        Radial distance in mm, NaN where invalid.
    """
    codes = _checked(raw, camera, "raw distance image")
    values = codes.astype(np.float64)
    invalid = (
        ~np.isfinite(values)
        | (values == camera.depth_invalid_code)
        | (values > camera.depth_max_valid_code)
    )
    mm = np.where(invalid, np.nan, values * camera.depth_unit_mm)
    if camera.distance_kind == "z":
        mm = mm / _ray_z(camera)
    return mm.astype(np.float32)


def encode_depth(
    distance_mm: np.ndarray, camera: CameraModel, *, dtype: type | np.dtype = np.uint16
) -> np.ndarray:
    """A device's raw distance image from the pipeline's (``decode_depth``'s inverse,
    up to the code quantisation): what the camera of this profile would deliver.

    Parameters
    ----------
    distance_mm : ndarray of shape (H, W)
        Radial distance along each pixel's ray, mm; NaN where invalid.
    camera : CameraModel
    dtype : numpy dtype, keyword-only
        Of the codes: an integer type rounds to the nearest code (uint16: mm codes as
        most devices send them); a float type keeps the fraction.

    Returns
    -------
    ndarray of shape (H, W) of ``dtype``
        z depth for a z-depth camera, radial distance otherwise, in ``depth_unit_mm``
        units; ``depth_invalid_code`` where the distance is NaN or beyond
        ``depth_max_valid_code``.
    """
    rho = _checked(distance_mm, camera, "distance image").astype(np.float64)
    mm = rho * _ray_z(camera) if camera.distance_kind == "z" else rho
    values = mm / camera.depth_unit_mm
    out_type = np.dtype(dtype)
    if out_type.kind in "iu":
        values = np.rint(values)
    invalid = ~np.isfinite(values) | (values > camera.depth_max_valid_code) | (values < 0)
    values = np.where(invalid, camera.depth_invalid_code, values)
    if out_type.kind in "iu":
        info = np.iinfo(out_type)
        if camera.depth_invalid_code < info.min or camera.depth_max_valid_code > info.max:
            raise ValueError(
                f"{out_type} cannot hold the camera's codes (invalid "
                f"{camera.depth_invalid_code}, largest valid {camera.depth_max_valid_code})"
            )
    return values.astype(out_type)
