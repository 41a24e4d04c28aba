"""Images for people to look at, beside the exact ones (docs/interop.md).

A 12-bit amplitude image stored as ``mono16`` looks black in a viewer that scales 16 bits
to the screen, and a float distance in millimetres shows as white or black; these are
the dashboard's views of both (gamma gray, turbo-coloured distance). The exact data
stays in the ``/tof/gray`` and ``/tof/distance`` channels.
"""

from __future__ import annotations

import cv2
import numpy as np

#: the EPC660's 12-bit full scale (tofpose.sim.render.FULL_SCALE_COUNTS)
FULL_SCALE_COUNTS = 4095


def gray_to_u8(gray: np.ndarray, full_scale_counts: float = FULL_SCALE_COUNTS) -> np.ndarray:
    """(H, W) uint16 counts -> (H, W) uint8, gamma 0.5 so that the dark plate stays
    visible beside bright reflectors; the camera's full scale (``CameraModel.
    full_scale_counts``: 4095 for the EPC660, 65535 for a 16-bit device) maps to 255 (the
    dashboard's view)."""
    if not full_scale_counts > 0:
        raise ValueError(f"full_scale_counts must be positive, got {full_scale_counts}")
    g = np.clip(gray.astype(np.float32) / np.float32(full_scale_counts), 0.0, 1.0)
    return np.round(255.0 * np.sqrt(g)).astype(np.uint8)


def distance_to_bgr(
    distance_mm: np.ndarray, range_mm: tuple[float, float] | None = None
) -> np.ndarray:
    """(H, W) float mm -> (H, W, 3) uint8 turbo colour map; invalid (NaN) pixels black.

    range_mm : colour scale limits; default the 2nd-98th percentile of valid pixels.
    """
    d = np.asarray(distance_mm, np.float32)
    valid = np.isfinite(d)
    if range_mm is None:
        if valid.any():
            lo, hi = np.percentile(d[valid], [2.0, 98.0])
        else:
            lo, hi = 0.0, 1.0
    else:
        lo, hi = range_mm
    hi = max(hi, lo + 1.0)
    x = np.zeros(d.shape, np.uint8)
    x[valid] = np.round(255.0 * np.clip((d[valid] - lo) / (hi - lo), 0.0, 1.0)).astype(np.uint8)
    bgr = cv2.applyColorMap(x, cv2.COLORMAP_TURBO)
    bgr[~valid] = 0
    return bgr


def distance_to_rgb(distance_mm: np.ndarray) -> np.ndarray:
    """``distance_to_bgr`` in RGB order (what ``rgb8`` images carry)."""
    return np.ascontiguousarray(distance_to_bgr(distance_mm)[..., ::-1])
