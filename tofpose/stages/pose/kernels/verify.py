"""The physical checks of a fitted pose against its frame (``solve.PoseSolver.verify``),
compiled: the reflectors' depths and the dark-marker check."""

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
