"""The physical checks of a fitted pose against its frame (ours; ``kernels.verify``,
``solve.PoseSolver.verify``) stated in NumPy: every reflector in front of the camera,
and no clearly visible unmatched reflector where the frame is dark; the matched
reflectors' aperture photometry (``photometry``)."""

from __future__ import annotations

import numpy as np

from tofpose.core.reference.camera import project
from tofpose.stages.pose.constants import BEHIND_CAMERA, CONSISTENT, DARK_REFLECTOR

#: a reflector is tested when its image is at least this many px across ...
MIN_TESTED_PX = 2.5
#: ... its disc lies this many diameters (+ ``EDGE_MARGIN_PX``) inside the image ...
EDGE_MARGIN_DIAMETERS = 0.75
EDGE_MARGIN_PX = 2.0
#: ... and no other reflector's image centre lies within this many of its diameters
CLEAR_DIAMETERS = 1.5
#: it is dark when no active pixel lies within d / 3 px (at least 1) of its centre
SEARCH_DIVISOR = 3.0


def pose_check(catalog, matched, R, t, camera, gray, threshold, dark_check):
    """The pose (R (3, 3), t (3,)) against the frame. ``BEHIND_CAMERA`` when any
    reflector's centre R x + t has z <= 0; else (with ``dark_check``) ``DARK_REFLECTOR``
    for the first reflector in catalog order that is unmatched, imaged d_px = fx d / z
    >= ``MIN_TESTED_PX`` across at (u, v) = its projected centre (Eq. 7 with the lens),
    inside the image by 0.75 d_px + 2 px (``m <= u < W - m``, the same for v), with no
    other reflector's image within 1.5 d_px, and with no active pixel (``gray >=
    threshold`` in float32) in the square of half-width r = max(1, round(d_px / 3))
    (half to even) about (round(u), round(v)), clipped to the image; else
    ``CONSISTENT``.

    catalog : xyz (N, 3) and radii_mm (N,) (a ``core.records.CatalogRecord``, read by
    field name; the diameters d are 2 r); matched (N,) bool; camera : fx and the lens
    (K, dist) of a ``core.records.CameraRecord``; gray (H, W) float32.
    Returns (outcome, reflector index, u, v): the dark reflector's, -1 and NaN
    otherwise."""
    centres = np.asarray(catalog.xyz, float) @ R.T + t
    if (centres[:, 2] <= 0).any():
        return BEHIND_CAMERA, -1, np.nan, np.nan
    if not dark_check:
        return CONSISTENT, -1, np.nan, np.nan
    uv = project(centres, camera.K, camera.dist)
    active = gray >= np.float32(threshold)
    h, w = gray.shape
    d_px = camera.fx * (2.0 * np.asarray(catalog.radii_mm, float)) / centres[:, 2]
    gaps = np.linalg.norm(uv[:, None, :] - uv[None, :, :], axis=-1)
    np.fill_diagonal(gaps, np.inf)
    for i in range(len(centres)):
        u, v = uv[i]
        margin = EDGE_MARGIN_DIAMETERS * d_px[i] + EDGE_MARGIN_PX
        tested = (
            not matched[i]
            and d_px[i] >= MIN_TESTED_PX
            and margin <= u < w - margin
            and margin <= v < h - margin
            and gaps[i].min() >= CLEAR_DIAMETERS * d_px[i]
        )
        if not tested:
            continue
        r = max(1, round(d_px[i] / SEARCH_DIVISOR))
        iu, iv = round(u), round(v)
        window = active[max(iv - r, 0) : iv + r + 1, max(iu - r, 0) : iu + r + 1]
        if not window.any():
            return DARK_REFLECTOR, i, float(u), float(v)
    return CONSISTENT, -1, np.nan, np.nan


def aperture_returns(
    gray, uv, radius_px, full_scale, margin_px, gap_px, width_px, mad_to_sigma
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``kernels.verify.aperture_returns`` in NumPy: each aperture's pixels by their
    distance from its centroid, the annulus' median and MAD."""
    g = np.asarray(gray, dtype=np.float64)
    h, w = g.shape
    m = len(uv)
    flux, noise, per_area = np.zeros(m), np.full(m, np.inf), np.zeros(m)
    saturated = np.zeros(m, bool)
    for i in range(m):
        u, v = float(uv[i, 0]), float(uv[i, 1])
        r_ap = float(radius_px[i]) + margin_px
        r_in = r_ap + gap_px
        r_out = r_in + width_px
        v0, v1 = max(int(v - r_out) - 1, 0), min(int(v + r_out) + 2, h)
        u0, u1 = max(int(u - r_out) - 1, 0), min(int(u + r_out) + 2, w)
        if v0 >= v1 or u0 >= u1:
            continue
        rows, cols = np.mgrid[v0:v1, u0:u1]
        d = np.hypot(cols - u, rows - v)
        window = g[v0:v1, u0:u1]
        inside = d < r_ap
        ring = window[(d >= r_in) & (d < r_out)]
        if not inside.any() or ring.size < 4:
            continue
        level = float(np.median(ring))
        spread = mad_to_sigma * float(np.median(np.abs(ring - level)))
        flux[i] = float(np.sum(window[inside])) - int(inside.sum()) * level
        noise[i] = max(spread, 1.0) * float(np.sqrt(inside.sum()))
        per_area[i] = flux[i] / (np.pi * float(radius_px[i]) ** 2)
        saturated[i] = bool(np.any(window[inside] >= full_scale))
    return flux, noise, per_area, saturated
