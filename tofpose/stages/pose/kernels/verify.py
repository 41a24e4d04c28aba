"""The physical checks of a fitted pose against its frame (``solve.PoseSolver.verify``),
compiled: the reflectors' depths, the dark-marker check and the matched reflectors'
aperture photometry (``photometry``)."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.camera import project
from tofpose.stages.pose.constants import BEHIND_CAMERA, CONSISTENT, DARK_REFLECTOR


@jit
def pose_check(catalog, matched, R, t, camera, gray, threshold, dark_check):
    """Whether the pose (R, t) puts every reflector in front of the camera, and (with
    ``dark_check``) whether a reflector that is not matched but should be clearly
    visible falls where the frame has no active pixel.

    catalog : a ``records.CatalogRecord`` (N reflectors; diameters 2 r); matched (N,)
    bool; camera : a ``records.CameraRecord``; gray (H, W) float32 and threshold : the
    frame and its I_t (the active set is ``gray >= threshold`` in
    float32, as ``levels.threshold_mask`` has it). A reflector is tested when it is at
    least 2.5 px across, its disc lies inside the image with a margin of 3/4 diameter
    + 2 px, and no other reflector's image is within 1.5 diameters (a merged pair gives
    no clean prediction); it is dark when no pixel within d/3 px (at least 1) of its
    projected centre is active. Returns (outcome, reflector index, u, v) px, the first
    dark reflector in catalog order (-1 and NaN otherwise)."""
    xyz, radii, fx = catalog.xyz, catalog.radii_mm, camera.fx
    n = xyz.shape[0]
    centres = np.empty((n, 3))
    for i in range(n):
        for a in range(3):
            centres[i, a] = R[a, 0] * xyz[i, 0] + R[a, 1] * xyz[i, 1] + R[a, 2] * xyz[i, 2] + t[a]
        if centres[i, 2] <= 0:
            return BEHIND_CAMERA, -1, np.nan, np.nan
    if not dark_check:
        return CONSISTENT, -1, np.nan, np.nan
    uv = project(centres, fx, camera.fy, camera.cx, camera.cy, camera.dist)
    h, w = gray.shape
    t32 = np.float32(threshold)
    for i in range(n):
        d_px = fx * (2.0 * radii[i]) / centres[i, 2]
        if matched[i] or d_px < 2.5:
            continue
        u, v = uv[i, 0], uv[i, 1]
        m = 0.75 * d_px + 2
        if not (m <= u < w - m and m <= v < h - m):
            continue
        nearest = np.inf
        for j in range(n):
            if j != i:
                nearest = min(nearest, np.hypot(uv[j, 0] - u, uv[j, 1] - v))
        if nearest < 1.5 * d_px:
            continue
        r = max(1, int(np.rint(d_px / 3)))  # rint: half to even, as Python's round
        iu, iv = int(np.rint(u)), int(np.rint(v))
        lit = False
        for row in range(max(iv - r, 0), min(iv + r + 1, h)):
            for col in range(max(iu - r, 0), min(iu + r + 1, w)):
                if gray[row, col] >= t32:
                    lit = True
        if not lit:
            return DARK_REFLECTOR, i, u, v
    return CONSISTENT, -1, np.nan, np.nan


@jit
def aperture_returns(gray, uv, radius_px, full_scale, margin_px, gap_px, width_px, mad_to_sigma):
    """Aperture photometry of m reflectors of the (H, W) frame ``gray`` at their centroids
    ``uv`` (m, 2) px with predicted image radii ``radius_px`` (m,) px: the sum over a
    disc of radius ``radius_px + margin_px`` of the counts above the median of an annulus
    ``gap_px`` outside it and ``width_px`` wide. Returns (flux counts, its 1-sigma noise:
    the annulus' MAD spread (at least 1 count) times sqrt of the disc's pixels, flux per
    predicted disc area (counts / px^2), whether a disc pixel is at ``full_scale``), each
    (m,); an aperture off the frame or with fewer than 4 annulus pixels: 0, inf, 0,
    False."""
    h, w = gray.shape
    m = uv.shape[0]
    flux = np.zeros(m)
    noise = np.full(m, np.inf)
    per_area = np.zeros(m)
    saturated = np.zeros(m, np.bool_)
    for i in range(m):
        u, v = uv[i, 0], uv[i, 1]
        r_ap = radius_px[i] + margin_px
        r_in = r_ap + gap_px
        r_out = r_in + width_px
        v0, v1 = max(int(v - r_out) - 1, 0), min(int(v + r_out) + 2, h)
        u0, u1 = max(int(u - r_out) - 1, 0), min(int(u + r_out) + 2, w)
        if v0 >= v1 or u0 >= u1:
            continue
        ring = np.empty((v1 - v0) * (u1 - u0))
        n_ring, n_in, total = 0, 0, 0.0
        clipped = False
        for row in range(v0, v1):
            for col in range(u0, u1):
                d = np.hypot(col - u, row - v)
                x = float(gray[row, col])
                if d < r_ap:
                    total += x
                    n_in += 1
                    if x >= full_scale:
                        clipped = True
                elif r_in <= d < r_out:
                    ring[n_ring] = x
                    n_ring += 1
        if n_in == 0 or n_ring < 4:
            continue
        level = np.median(ring[:n_ring])
        spread = mad_to_sigma * np.median(np.abs(ring[:n_ring] - level))
        flux[i] = total - n_in * level
        noise[i] = max(spread, 1.0) * np.sqrt(n_in)
        per_area[i] = flux[i] / (np.pi * radius_px[i] ** 2)
        saturated[i] = clipped
    return flux, noise, per_area, saturated
