"""HDF5 recording -> Rerun recording (``tofpose export rrd``; docs/interop.md).

Rerun opens our MCAP files too, but its importer draws neither Foxglove's image
annotations nor any number of our JSON channels, so an MCAP gives it no time series and
no overlay. This export logs with ``rerun-sdk`` (an optional dependency: ``pip install
rerun-sdk``; imported only here) the entities Rerun's MCAP importer makes of the same
recording, on the same timeline and named frames, so that the shipped blueprint
(``rerun_blueprint``, embedded in the file) serves both, and adds:

- ``/tof/gray_preview/overlay``: the dashboard's overlay on the gray image (matched
  blobs green with their catalog id, unmatched candidates red, rejected blobs orange
  with the gate's name), circles in pixels (Rerun's pixel centres sit at +0.5, as
  Foxglove's);
- ``/tofpose/target_model``: the catalog's reflectors and the plate in the ``target``
  frame, so the target stands at its estimated pose;
- ``/tofpose/trail``: the estimated target origin over the last ``TRAIL_POSES`` poses;
- ``/tofpose/series/{position,attitude}/...``: scalars per frame, x/y/z mm and
  pitch/yaw/roll deg (the estimate, and the lab's reference when the recording has
  one); ``/tofpose/series/turntable/{encoders,setpoint}/<axis>_deg`` the rotary axes and
  ``/tofpose/series/rail/...`` the rail (mm, in no view of the blueprint: add one).

Lengths in the 3-D entities are metres (Rerun's and Foxglove's convention), in the
series millimetres and degrees as everywhere else.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import facing_euler_deg, quaternion_wxyz_from_rotation
from tofpose.io.interop import rerun_blueprint as bp
from tofpose.io.interop import topics
from tofpose.io.interop.mcap_export import message_times_ns, pose_at
from tofpose.io.interop.motion_track import MotionTrack, read_motion_track
from tofpose.io.interop.previews import distance_to_rgb, gray_to_u8
from tofpose.io.recording import Recording
from tofpose.pipeline import PosePipeline, PoseResult

TRAIL_POSES = 300
MATCHED_RGB, UNMATCHED_RGB, REJECTED_RGB = (40, 200, 90), (230, 50, 50), (240, 150, 30)
#: the series' colours per axis: the estimate strong, the lab reference pale
SERIES_RGB = {
    "estimate": ((220, 50, 50), (40, 160, 60), (40, 90, 220)),
    "lab_reference": ((240, 160, 160), (150, 210, 150), (150, 180, 240)),
}
_CIRCLE = np.stack(
    [np.cos(np.linspace(0, 2 * np.pi, 25)), np.sin(np.linspace(0, 2 * np.pi, 25))], axis=1
)


def _circle(u_px: float, v_px: float, diameter_px: float) -> np.ndarray:
    """(25, 2) polyline of a circle around pixel (u, v) in Rerun's image coordinates."""
    return np.array([u_px + 0.5, v_px + 0.5]) + _CIRCLE * (diameter_px / 2.0)


def overlay_strips(result: PoseResult) -> tuple[list[np.ndarray], list[tuple], list[str]]:
    """The overlay as (circles (25, 2) each, colours, labels), the dashboard's sizes:
    matched blobs by their area, unmatched candidates 6 px, rejected by their size."""
    strips, colours, labels = [], [], []
    for m in result.matched:
        d_px = 2.0 * max(float(np.sqrt(m.area_px / np.pi)), 1.0) + 2.0
        strips.append(_circle(float(m.centroid_uv[0]), float(m.centroid_uv[1]), d_px))
        colours.append(MATCHED_RGB)
        labels.append(str(m.catalog_id))
    for u, v, _d in result.unmatched:
        strips.append(_circle(float(u), float(v), 6.0))
        colours.append(UNMATCHED_RGB)
        labels.append("")
    for rb in result.rejected:
        strips.append(_circle(float(rb.u_px), float(rb.v_px), max(float(rb.diameter_px), 2.0) + 2))
        colours.append(REJECTED_RGB)
        labels.append(str(rb.reason))
    return strips, colours, labels


def _transform(rr, R: np.ndarray, t_mm: np.ndarray, child: str):
    w, x, y, z = quaternion_wxyz_from_rotation(R)
    return rr.Transform3D(
        translation=np.asarray(t_mm, float) / 1000.0,
        quaternion=rr.Quaternion(xyzw=[x, y, z, w]),
        parent_frame=topics.CAMERA_FRAME_ID,
        child_frame=child,
    )


def _log_static(rr, stream, camera: CameraModel, catalog: Catalog | None) -> None:
    K = [[camera.fx, 0.0, camera.cx], [0.0, camera.fy, camera.cy], [0.0, 0.0, 1.0]]
    stream.log(
        topics.CALIBRATION,
        rr.Pinhole(
            image_from_camera=K,
            resolution=[camera.width, camera.height],
            camera_xyz=rr.ViewCoordinates.RDF,
            parent_frame=topics.CAMERA_FRAME_ID,
            child_frame=bp.IMAGE_PLANE_FRAME,
            image_plane_distance=0.3,
        ),
        static=True,
    )
    for entity in (topics.GRAY_PREVIEW, topics.DISTANCE_PREVIEW, bp.OVERLAY):
        stream.log(entity, rr.CoordinateFrame(bp.IMAGE_PLANE_FRAME), static=True)
    for entity in (topics.REFLECTORS, topics.TARGET_ORIGIN, bp.TRAIL):
        stream.log(entity, rr.CoordinateFrame(topics.CAMERA_FRAME_ID), static=True)
    if catalog is not None:
        w_mm, h_mm = catalog.plate_size_mm
        stream.log(
            f"{bp.TARGET_MODEL}/reflectors",
            rr.Points3D(
                catalog.positions_mm / 1000.0,
                radii=catalog.diameters_mm / 2000.0,
                labels=[str(i) for i in catalog.ids],
                colors=[MATCHED_RGB],
            ),
            rr.CoordinateFrame(topics.TARGET_FRAME_ID),
            static=True,
        )
        stream.log(
            f"{bp.TARGET_MODEL}/plate",
            rr.Boxes3D(
                half_sizes=[[w_mm / 2000.0, h_mm / 2000.0, 0.005]],
                centers=[[0.0, 0.0, -0.005]],
                colors=[(200, 200, 205)],
            ),
            rr.CoordinateFrame(topics.TARGET_FRAME_ID),
            static=True,
        )
    for name, colours in SERIES_RGB.items():
        label = name.replace("_", " ")
        for k, axis in enumerate(("x_mm", "y_mm", "z_mm")):
            style = rr.SeriesLines(names=f"{axis[0]} mm, {label}", colors=colours[k])
            stream.log(f"{bp.POSITION_SERIES}/{name}/{axis}", style, static=True)
        for k, axis in enumerate(("pitch_deg", "yaw_deg", "roll_deg")):
            style = rr.SeriesLines(names=f"{axis[:-4]} deg, {label}", colors=colours[k])
            stream.log(f"{bp.ATTITUDE_SERIES}/{name}/{axis}", style, static=True)


def _motion_paths(motion: MotionTrack) -> list[tuple[str, str]]:
    """(series entity, field) per axis: the rotary axes (deg) in the turntable's plot,
    the others (the rail, mm) apart."""
    return [
        (bp.TURNTABLE_SERIES if unit == "deg" else bp.RAIL_SERIES, field)
        for unit, field in zip(motion.units, motion.fields, strict=True)
    ]


def _log_motion_styles(rr, stream, motion: MotionTrack) -> None:
    for (series, field), axis in zip(_motion_paths(motion), motion.axes, strict=True):
        unit = field.rsplit("_", 1)[1]
        for kind, label in (("encoders", "encoder"), ("setpoint", "set-point")):
            style = rr.SeriesLines(names=f"{axis} {unit}, {label}")
            stream.log(f"{series}/{kind}/{field}", style, static=True)


def _log_result(rr, stream, result: PoseResult, trail: list[np.ndarray]) -> None:
    strips, colours, labels = overlay_strips(result)
    stream.log(bp.OVERLAY, rr.LineStrips2D(strips, colors=colours, labels=labels))
    pts = [np.asarray(m.point_mm, float) / 1000.0 for m in result.matched]
    stream.log(
        topics.REFLECTORS,
        rr.Points3D(np.reshape(pts, (-1, 3)), colors=[MATCHED_RGB], radii=0.01),
    )
    if not (result.ok and result.R is not None and result.t_mm is not None):
        return
    stream.log(topics.POSE_TRANSFORM, _transform(rr, result.R, result.t_mm, topics.TARGET_FRAME_ID))
    origin = np.asarray(result.t_mm, float) / 1000.0
    stream.log(topics.TARGET_ORIGIN, rr.Points3D([origin], radii=0.008, colors=[MATCHED_RGB]))
    trail.append(origin)
    del trail[:-TRAIL_POSES]
    stream.log(bp.TRAIL, rr.LineStrips3D([np.array(trail)], colors=[MATCHED_RGB]))
    _log_series(rr, stream, "estimate", result.R, result.t_mm)


def _log_series(rr, stream, name: str, R: np.ndarray, t_mm: np.ndarray) -> None:
    for axis, v in zip(("x_mm", "y_mm", "z_mm"), t_mm, strict=True):
        stream.log(f"{bp.POSITION_SERIES}/{name}/{axis}", rr.Scalars(float(v)))
    for axis, v in zip(("pitch_deg", "yaw_deg", "roll_deg"), facing_euler_deg(R), strict=True):
        stream.log(f"{bp.ATTITUDE_SERIES}/{name}/{axis}", rr.Scalars(float(v)))


def export_rrd(
    rec: Recording,
    out: str | Path,
    pipeline: PosePipeline | None = None,
    *,
    progress: bool = True,
    overwrite: bool = False,
) -> dict[str, int]:
    """Write ``rec`` to the Rerun recording ``out`` with the shipped blueprint as its
    default; with a ``pipeline``, each frame's estimate too. Times: the MCAP export's
    (``mcap_export.message_times_ns``: the wall clock when the recording has it).

    Returns {"frames": N, "ok": frames with a pose}. ValueError when ``out`` exists
    (without ``overwrite``); ImportError naming the package when rerun-sdk is missing."""
    try:
        import rerun as rr
    except ImportError as exc:
        raise ImportError(
            "tofpose export rrd needs the rerun-sdk package (pip install rerun-sdk)"
        ) from exc
    out = Path(out)
    if out.exists() and not overwrite:
        raise ValueError(f"{out} exists (pass --force to overwrite it)")
    times_ns = message_times_ns(rec)
    motion = read_motion_track(rec.path, rec.n_frames)
    catalog = pipeline.catalog if pipeline is not None else rec.catalog
    partial = out.with_name(out.name + ".partial")
    stream: Any = rr.RecordingStream(bp.APPLICATION_ID, recording_id=rec.path.stem)
    stream.save(partial, default_blueprint=bp.build_blueprint())
    n_ok, done = 0, False
    trail: list[np.ndarray] = []
    try:
        _log_static(rr, stream, rec.camera, catalog)
        if motion is not None:
            _log_motion_styles(rr, stream, motion)
        for i in tqdm(
            range(rec.n_frames),
            desc="export rrd",
            unit="frame",
            disable=not progress,
            file=sys.stderr,
        ):
            gray, dist, t = rec.frame(i)
            stream.set_time(bp.TIMELINE, timestamp=np.datetime64(int(times_ns[i]), "ns"))
            stream.set_time("frame", sequence=i)
            stream.log(
                topics.GRAY_PREVIEW,
                rr.Image(gray_to_u8(gray, rec.camera.full_scale_counts), color_model="L"),
            )
            stream.log(topics.DISTANCE_PREVIEW, rr.Image(distance_to_rgb(dist), color_model="RGB"))
            if pipeline is not None:
                result = pipeline.process(gray, dist, t)
                n_ok += int(result.ok)
                _log_result(rr, stream, result, trail)
            for name, pose, child in (
                ("truth", pose_at(rec.truth_R, rec.truth_t_mm, i), topics.TRUTH_FRAME_ID),
                (
                    "reference",
                    pose_at(rec.reference_R, rec.reference_t_mm, i),
                    topics.REFERENCE_FRAME_ID,
                ),
            ):
                if pose is None or not np.all(np.isfinite(pose[1])):
                    continue
                topic = topics.TRUTH_TRANSFORM if name == "truth" else topics.REFERENCE_TRANSFORM
                stream.log(topic, _transform(rr, pose[0], pose[1], child))
                if name == "reference":
                    _log_series(rr, stream, "lab_reference", *pose)
            if motion is not None:
                for path, enc, target in zip(
                    _motion_paths(motion), motion.positions[i], motion.targets[i], strict=True
                ):
                    for kind, v in (("encoders", enc), ("setpoint", target)):
                        if np.isfinite(v):
                            stream.log(f"{path[0]}/{kind}/{path[1]}", rr.Scalars(v))
        done = True
    finally:
        stream.flush()
        stream.disconnect()
        if done:
            partial.replace(out)
        else:
            partial.unlink(missing_ok=True)
    return {"frames": rec.n_frames, "ok": n_ok}
