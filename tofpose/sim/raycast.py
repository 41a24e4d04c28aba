"""The renderer's ray caster, compiled: the nearest surface along each pixel ray.

The scene in the camera frame is a wall plane (optional), the target plate (a rectangle)
and flat discs (the reflectors, then clutter). Each ray from the camera centre is
intersected with each surface and the nearest hit in front of the camera is kept; a disc
is tried only by rays within its angular radius of its centre (``1.001`` x, against
rounding). The arithmetic is that of the NumPy caster it replaced (``SceneInCamera``
kept the same contract); a frame casts its 76,800 pixel rays plus the super-samples of
the mixed pixels once per phase sub-frame, which in NumPy cost ~12 ms a call.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit

NO_HIT, WALL, PLATE, FIRST_DISC = 0, 1, 2, 3


@jit
def cast_rays(
    bearings,
    wall_point,
    has_wall,
    plate_centre,
    plate_normal,
    plate_axes,
    plate_half,
    disc_centres,
    disc_normals,
    disc_radii,
):
    """Nearest intersection of unit rays ``bearings`` (M, 3) with the scene.

    wall_point (3,) on the wall (parallel to the plate) when ``has_wall``; plate_centre,
    plate_normal (3,), plate_axes (2, 3) its in-plane axes, plate_half (2,) its half size
    (mm); disc_centres, disc_normals (D, 3), disc_radii (D,) mm.
    Returns distance_mm (M,) (inf: no hit), surface id (M,) uint8 (NO_HIT, WALL, PLATE,
    FIRST_DISC + k) and the cosine of incidence (M,).
    """
    m = bearings.shape[0]
    n_disc = disc_radii.shape[0]
    best = np.full(m, np.inf)
    sid = np.zeros(m, np.uint8)
    cos_inc = np.zeros(m)
    nx, ny, nz = plate_normal[0], plate_normal[1], plate_normal[2]
    wall_n = wall_point[0] * nx + wall_point[1] * ny + wall_point[2] * nz
    plate_n = plate_centre[0] * nx + plate_centre[1] * ny + plate_centre[2] * nz
    c_unit = np.empty((n_disc, 3))
    cos_half = np.empty(n_disc)
    centre_n = np.empty(n_disc)
    for k in range(n_disc):
        dc = np.sqrt(disc_centres[k, 0] ** 2 + disc_centres[k, 1] ** 2 + disc_centres[k, 2] ** 2)
        for j in range(3):
            c_unit[k, j] = disc_centres[k, j] / dc
        sin_half = min(max(disc_radii[k] * 1.001 / dc, 0.0), 1.0)
        cos_half[k] = np.sqrt(1.0 - sin_half**2)
        centre_n[k] = (
            disc_centres[k, 0] * disc_normals[k, 0]
            + disc_centres[k, 1] * disc_normals[k, 1]
            + disc_centres[k, 2] * disc_normals[k, 2]
        )
    for i in range(m):
        bx, by, bz = bearings[i, 0], bearings[i, 1], bearings[i, 2]
        denom = bx * nx + by * ny + bz * nz
        if denom != 0.0:
            if has_wall:
                s = wall_n / denom
                if s > 0 and s < best[i]:
                    best[i], sid[i], cos_inc[i] = s, WALL, abs(denom)
            s = plate_n / denom
            if s > 0 and np.isfinite(s):
                px = bx * s - plate_centre[0]
                py = by * s - plate_centre[1]
                pz = bz * s - plate_centre[2]
                lx = px * plate_axes[0, 0] + py * plate_axes[0, 1] + pz * plate_axes[0, 2]
                ly = px * plate_axes[1, 0] + py * plate_axes[1, 1] + pz * plate_axes[1, 2]
                if abs(lx) <= plate_half[0] and abs(ly) <= plate_half[1] and s < best[i]:
                    best[i], sid[i], cos_inc[i] = s, PLATE, abs(denom)
        for k in range(n_disc):
            if bx * c_unit[k, 0] + by * c_unit[k, 1] + bz * c_unit[k, 2] < cos_half[k]:
                continue
            dn = bx * disc_normals[k, 0] + by * disc_normals[k, 1] + bz * disc_normals[k, 2]
            if not dn < 0:  # the disc faces the camera
                continue
            s = centre_n[k] / dn
            if not (s > 0 and s < best[i]):
                continue
            qx = bx * s - disc_centres[k, 0]
            qy = by * s - disc_centres[k, 1]
            qz = bz * s - disc_centres[k, 2]
            if qx * qx + qy * qy + qz * qz <= disc_radii[k] ** 2:
                best[i], sid[i], cos_inc[i] = s, FIRST_DISC + k, -dn
    return best, sid, cos_inc
