"""Each pixel's true radial distance to the known target at a known pose, by ray casting
the simulator's target shape: the truth a range calibration is fitted against
(``tofpose.calibration.range``), for a simulated run and for a recording with reference
poses alike."""

from __future__ import annotations

import cv2
import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.sim.scene import FIRST_DISC, NO_HIT, TargetScene


def true_pixel_distances(
    camera: CameraModel,
    catalog: Catalog,
    T_camera_target: RigidTransform,
    reflectors_only: bool = True,
) -> np.ndarray:
    """Each pixel's true radial distance to the known target, NaN where the ray misses it
    or lands within a pixel of a surface edge. (H, W).

    ``reflectors_only`` (default) keeps the reflector discs only: they are what the
    pipeline ranges, and the dim plate beside them is where lens scatter mixes in the
    reflectors' phase, an error that would otherwise be fitted as an amplitude effect.
    """
    scene = TargetScene(catalog=catalog, wall_distance_mm=None)
    d, sid, _ = scene.in_camera(T_camera_target).raycast(camera.pixel_bearings().reshape(-1, 3))
    h, w = camera.height, camera.width
    sid = sid.reshape(h, w)
    edge = cv2.dilate(sid, np.ones((3, 3), np.uint8)) != cv2.erode(sid, np.ones((3, 3), np.uint8))
    out = d.reshape(h, w).astype(float)
    out[(sid == NO_HIT) | edge] = np.nan
    if reflectors_only:
        out[sid < FIRST_DISC] = np.nan
    return out
