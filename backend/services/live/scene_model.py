"""What the 3-D scene shows, computed from one live sample: pure functions, no viser.

Scene frame = the lab frame L (docs/architecture.md §6), in metres: at all axes zero the
camera frame coincides with L (x right, y down, z towards the target). The camera rides
the turntable's inner axis, so its pose in L follows the encoders; the target stands.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.lab.kinematics import axes_transform
from tofpose.pipeline import PoseResult

MATCHED, UNMATCHED, OUT_OF_VIEW = "matched", "unmatched", "out_of_view"
STATE_COLOURS = {  # RGB 0-255
    MATCHED: (40, 180, 90),
    UNMATCHED: (240, 150, 30),
    OUT_OF_VIEW: (130, 130, 130),
}


def lab_camera_pose(encoders: dict[str, float] | None) -> RigidTransform:
    """T_lab_camera from encoder readings (nominal mount: the identity); the lab origin
    when the source reports no encoders (a replayed recording, no motion system)."""
    if not encoders:
        return RigidTransform.identity()
    return axes_transform(encoders)


def reflector_states(
    catalog: Catalog, result: PoseResult, camera: CameraModel, T_camera_target
) -> list[str]:
    """Per catalog reflector (catalog order): matched, unmatched (the pose puts it in
    the image, facing the camera, but the pipeline did not match it) or out_of_view.

    ``T_camera_target`` is the pose used to decide visibility (the estimate, else the
    truth); without any pose every reflector that is not matched is out_of_view.
    """
    matched_ids = {m.catalog_id for m in result.matched}
    states = []
    if T_camera_target is not None:
        p = catalog.positions_mm @ T_camera_target.R.T + T_camera_target.t_mm
        normal_cam = T_camera_target.R[:, 2]
        in_front = p[:, 2] > 1.0
        uv = np.full((len(p), 2), -1.0)
        if in_front.any():
            uv[in_front] = camera.project(p[in_front])
        in_image = (
            in_front
            & (uv[:, 0] >= 0)
            & (uv[:, 0] <= camera.width - 1)
            & (uv[:, 1] >= 0)
            & (uv[:, 1] <= camera.height - 1)
        )
        facing = (p @ normal_cam) < 0  # the disc's normal points back at the camera
        visible = in_image & facing
    else:
        visible = np.zeros(len(catalog.ids), bool)
    for rid, vis in zip(catalog.ids, visible, strict=True):
        if int(rid) in matched_ids:
            states.append(MATCHED)
        else:
            states.append(UNMATCHED if vis else OUT_OF_VIEW)
    return states


@dataclass(frozen=True)
class DistanceCloud:
    """The back-projected distance image (Eq. 8), downsampled.

    points_m : (N, 3) in the camera frame, metres; colours : (N, 3) uint8 (gray level).
    step : pixel stride used in both image axes.
    """

    points_m: np.ndarray
    colours: np.ndarray
    step: int


def distance_cloud(
    camera: CameraModel, gray: np.ndarray, distance_mm: np.ndarray, max_points: int
) -> DistanceCloud:
    """Back-project every ``step``-th pixel with a valid distance, ``step`` the smallest
    stride that keeps at most ``max_points`` pixels. gray, distance_mm : (H, W)."""
    h, w = distance_mm.shape
    step = max(1, int(np.ceil(np.sqrt(h * w / max(max_points, 1)))))
    d = distance_mm[::step, ::step]
    e = camera.pixel_bearings()[::step, ::step]
    valid = np.isfinite(d) & (d > 0)
    pts = e[valid] * (d[valid][:, None] / 1000.0)
    g = gray[::step, ::step][valid].astype(np.float64)
    if g.size:
        lo, hi = np.percentile(g, (1.0, 99.5))
        level = np.clip((g - lo) / max(hi - lo, 1.0), 0.0, 1.0)
    else:
        level = g
    shade = (60 + 195 * level).astype(np.uint8)
    return DistanceCloud(pts.astype(np.float32), np.repeat(shade[:, None], 3, axis=1), step)
