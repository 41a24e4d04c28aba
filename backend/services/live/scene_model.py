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
    lab's reference or the truth); without any pose every reflector that is not matched
    is out_of_view.
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


# -- ground grid, scale and the pose trail ------------------------------------------------
GROUND_DROP_M = 1.0
"""The ground grid's plane lies this far below the lab origin (lab y points down): under
the turntable, where a floor would be, so that it cuts through neither camera nor target."""
TRAIL_POSES = 300
"""Estimated target positions the trail keeps (the newest; 30 s at the scene's 10 Hz)."""


def nice_step_m(extent_m: float, max_ticks: int = 10) -> float:
    """The scale's tick spacing, m: 1, 2 or 5 times a power of ten, the smallest that
    puts at most ``max_ticks`` ticks on ``extent_m``."""
    if not (extent_m > 0 and np.isfinite(extent_m)):
        raise ValueError(f"the scale's extent must be a positive length, got {extent_m} m")
    raw = extent_m / max_ticks
    power = 10.0 ** np.floor(np.log10(raw))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        if mantissa * power >= raw - 1e-12:
            return float(mantissa * power)
    raise AssertionError("unreachable: 10 x the power always covers raw")


def scene_extent_m(points_m: np.ndarray, margin_m: float = 1.0) -> float:
    """How far the grid and the scale reach from the lab origin, m: the farthest of
    ``points_m`` (N, 3) (camera and target, lab frame) along x or z plus ``margin_m``,
    rounded up to a whole metre; at least 2 m."""
    reach = float(np.max(np.abs(np.asarray(points_m, float)[:, [0, 2]]), initial=0.0))
    return max(2.0, float(np.ceil(reach + margin_m)))


@dataclass(frozen=True)
class ScaleMark:
    """One labelled tick of the scale: where (lab frame, m, on the ground plane) and what
    it reads (``"2 m"``)."""

    position_m: tuple[float, float, float]
    text: str


def _metres(value_m: float) -> str:
    return f"{value_m:g} m"


def scale_marks(extent_m: float, drop_m: float = GROUND_DROP_M) -> tuple[list[ScaleMark], float]:
    """The rulers along the lab's x and z axes on the ground plane (y = ``drop_m``): one
    mark per tick from 0 to ``extent_m`` along z (the rail, the boresight at zero axes)
    and from -extent/2 to extent/2 along x. Returns (marks, tick spacing in m)."""
    step = nice_step_m(extent_m)
    marks = [
        ScaleMark((0.0, drop_m, float(z)), _metres(float(z)))
        for z in np.arange(0.0, extent_m + step / 2, step)
    ]
    half = np.floor(extent_m / 2 / step) * step
    marks += [
        ScaleMark((float(x), drop_m, 0.0), _metres(float(x)))
        for x in np.arange(-half, half + step / 2, step)
        if abs(x) > step / 2  # 0 m is the z ruler's first mark
    ]
    return marks, step


def scale_segments(
    marks: list[ScaleMark], extent_m: float, drop_m: float = GROUND_DROP_M, tick_m: float = 0.08
) -> np.ndarray:
    """The rulers as line segments (M, 2, 3), m: the z axis from 0 to ``extent_m``, the x
    axis across, and a tick across the ruler at every mark."""
    half = extent_m / 2
    segments = [
        [(0.0, drop_m, 0.0), (0.0, drop_m, extent_m)],
        [(-half, drop_m, 0.0), (half, drop_m, 0.0)],
    ]
    for m in marks:
        x, y, z = m.position_m
        if x == 0.0:  # on the z ruler: a tick across it, along x
            segments.append([(-tick_m, y, z), (tick_m, y, z)])
        else:
            segments.append([(x, y, -tick_m), (x, y, tick_m)])
    return np.asarray(segments, float)


class PoseTrail:
    """The last ``max_poses`` estimated target positions (lab frame, m), oldest first."""

    def __init__(self, max_poses: int = TRAIL_POSES) -> None:
        if max_poses < 2:
            raise ValueError(f"a trail needs at least 2 poses, got max_poses={max_poses}")
        self.max_poses = max_poses
        self._points: list[np.ndarray] = []

    def add(self, position_m: np.ndarray) -> None:
        """Append one position (3,); the oldest goes when the trail is full."""
        p = np.asarray(position_m, float).reshape(3)
        if not np.all(np.isfinite(p)):
            raise ValueError(f"a trail position must be finite, got {p.tolist()}")
        self._points.append(p)
        del self._points[: -self.max_poses]

    def clear(self) -> None:
        self._points.clear()

    def __len__(self) -> int:
        return len(self._points)

    @property
    def points_m(self) -> np.ndarray:
        """(n, 3) positions, oldest first."""
        return np.array(self._points, float).reshape(-1, 3)

    def segments_m(self) -> np.ndarray:
        """(n - 1, 2, 3): the polyline through the positions as viser's line segments."""
        p = self.points_m
        return np.stack([p[:-1], p[1:]], axis=1)
