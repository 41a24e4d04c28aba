"""Which blobs saturate: a blob whose pixels reach the camera's full scale
(``CameraModel.full_scale_counts``) has clipped counts and no distance there, so the
integration time is too long for it (issue 49, item 2). The pipeline marks each matched
reflector with it (``MatchedReflector.saturated``) and names the saturating candidates in
a refused frame's reason, so that a user knows to shorten the exposure.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tofpose.stages.extraction.extraction import Blob, pixel_lists


def pixels_at_full_scale(
    gray: np.ndarray, flat: np.ndarray, starts: np.ndarray, *, full_scale_counts: float
) -> np.ndarray:
    """Whether each blob has a pixel at or above the camera's full scale.

    Parameters
    ----------
    gray : ndarray of shape (H, W), the frame's gray counts.
    flat : ndarray of shape (P,) int, flat indices (row * W + col) of the blobs' pixels,
        blob j's being ``flat[starts[j]:starts[j + 1]]`` (``extraction.pixel_lists``).
    starts : ndarray of shape (B + 1,) int, non-decreasing, ``starts[-1] == P``.
    full_scale_counts : the gray level at which the sensor clips (> 0).

    Returns
    -------
    ndarray of shape (B,) bool; False for a blob without pixels.
    """
    gray = np.asarray(gray)
    flat = np.asarray(flat, np.int64)
    starts = np.asarray(starts, np.int64)
    if gray.ndim != 2:
        raise ValueError(f"gray must be an (H, W) image, got shape {gray.shape}")
    if not full_scale_counts > 0:
        raise ValueError(f"full_scale_counts must be positive, got {full_scale_counts}")
    if starts.ndim != 1 or len(starts) < 1 or starts[0] != 0 or starts[-1] != len(flat):
        raise ValueError(
            f"starts must run from 0 to the {len(flat)} pixel indices, got "
            f"{starts[:1].tolist()} ... {starts[-1:].tolist()}"
        )
    if np.any(np.diff(starts) < 0):
        raise ValueError("starts must be non-decreasing")
    if len(flat) and (flat.min() < 0 or flat.max() >= gray.size):
        raise ValueError(f"pixel indices must lie in the {gray.shape} image")
    return pixel_lists_at_full_scale(gray, flat, starts, full_scale_counts)


def pixel_lists_at_full_scale(
    gray: np.ndarray, flat: np.ndarray, starts: np.ndarray, full_scale_counts: float
) -> np.ndarray:
    """``pixels_at_full_scale`` without its checks of the arguments: for the per-frame
    path, whose pixel lists the stages themselves built (every frame, acquisition and
    tracking). (B,) bool."""
    at_full_scale = gray.ravel()[flat] >= full_scale_counts  # (P,)
    # pixels at full scale before each start: blob j has those of [starts[j], starts[j+1])
    before = np.concatenate(([0], np.cumsum(at_full_scale, dtype=np.int64)))  # (P + 1,)
    return before[starts[1:]] > before[starts[:-1]]


def blobs_at_full_scale(
    gray: np.ndarray, blobs: Sequence[Blob], *, full_scale_counts: float
) -> np.ndarray:
    """(B,) bool: whether each blob has a pixel at or above ``full_scale_counts`` in
    ``gray`` (H, W) (``pixels_at_full_scale`` over the blobs' own pixel lists)."""
    flat, starts = pixel_lists(blobs)
    return pixel_lists_at_full_scale(np.asarray(gray), flat, starts, full_scale_counts)
