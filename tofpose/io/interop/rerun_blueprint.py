"""The Rerun blueprint shipped with the exports (docs/interop.md, "Opening it in Rerun").

One layout for both ways into Rerun: an MCAP export opened as it is (Rerun's importer
maps Foxglove's schemas to its archetypes, with the topics as entity paths and the
named frames ``camera``, ``camera_image_plane``, ``target``) and ``tofpose export rrd``
(``rerun_export``, which logs the same entities and adds what no MCAP channel gives
Rerun: the pose's time series and the image overlay). Built with ``rerun-sdk``'s
blueprint API (imported only here, when a blueprint is made):

- a 3-D view in the ``camera`` frame: the camera's frustum (``/tof/calibration``), the
  estimated and reference target frames, the reflectors and the target's origin with
  everything seen so far (the view's time range runs from the start to the cursor:
  the origin's points are the pose's trail);
- the gray and distance images (the overlay is drawn on the gray image in an ``.rrd``);
- time series of the position (mm), the attitude (deg) and the turntable.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from tofpose.io.interop import topics

#: the application id an ``.rrd`` export is logged under and the ``.rbl`` is saved for
APPLICATION_ID = "tofpose"
#: Rerun's timeline of an MCAP's log times; the ``.rrd`` export logs on the same one
TIMELINE = "message_log_time"
#: entity paths of the ``.rrd`` export's own entities (no MCAP channel)
SERIES = "/tofpose/series"
POSITION_SERIES = f"{SERIES}/position"
ATTITUDE_SERIES = f"{SERIES}/attitude"
TURNTABLE_SERIES = f"{SERIES}/turntable"  # the rotary axes, deg
RAIL_SERIES = f"{SERIES}/rail"  # the rail, mm (in no view: its scale would flatten the rest)
EYE_POSITION_M = (-2.5, -2.0, -1.5)
EYE_TARGET_M = (0.0, 0.0, 2.5)
TRAIL = "/tofpose/trail"
TARGET_MODEL = "/tofpose/target_model"
OVERLAY = f"{topics.GRAY_PREVIEW}/overlay"
#: the named frames of Rerun's MCAP importer (a Pinhole maps camera -> image plane)
IMAGE_PLANE_FRAME = "camera_image_plane"


def build_blueprint(*, series: bool = True) -> Any:
    """The layout as a ``rerun.blueprint.Blueprint``; without ``series`` the time series
    are left out (an MCAP gives Rerun none: its views would stay empty)."""
    import rerun.blueprint as rrb

    history = rrb.VisibleTimeRange(
        TIMELINE,
        start=rrb.TimeRangeBoundary.infinite(),
        end=rrb.TimeRangeBoundary.cursor_relative(),
    )
    scene = rrb.Spatial3DView(
        name="3-D: camera, target, reflectors (camera frame)",
        origin="/",
        contents=[
            f"+ {topics.CALIBRATION}",
            "+ /tofpose/**",
            f"- {SERIES}/**",
            f"- {topics.POSE}",  # InstancePoses3D: nothing to draw, the transform shows it
        ],
        spatial_information=rrb.SpatialInformation(
            target_frame=topics.CAMERA_FRAME_ID, show_axes=True
        ),
        # from behind the camera, up and to its left, along the boresight; camera frame
        # (x right, y down, z ahead), m
        eye_controls=rrb.EyeControls3D(
            position=EYE_POSITION_M, look_target=EYE_TARGET_M, eye_up=(0.0, -1.0, 0.0)
        ),
        time_ranges=history,
    )
    images = rrb.Vertical(
        rrb.Spatial2DView(name="gray, with the overlay", origin=topics.GRAY_PREVIEW),
        rrb.Spatial2DView(name="distance", origin=topics.DISTANCE_PREVIEW),
    )
    plots = rrb.Vertical(
        rrb.TimeSeriesView(name="position (mm)", origin=POSITION_SERIES),
        rrb.TimeSeriesView(name="attitude (deg)", origin=ATTITUDE_SERIES),
        rrb.TimeSeriesView(name="turntable: encoders and set-point (deg)", origin=TURNTABLE_SERIES),
    )
    columns: list[Any] = [scene, images, plots] if series else [scene, images]
    return rrb.Blueprint(
        rrb.Horizontal(*columns, column_shares=[2, 1, 1][: len(columns)]),
        collapse_panels=True,
    )


def mcap_application_id(mcap_path: str | Path) -> str:
    """The application id Rerun's viewer gives an MCAP file it opens: the file's name
    without ``.mcap`` (``rerun campaign-3.mcap`` -> ``campaign-3``). A blueprint applies
    to the recordings of its application id only."""
    return Path(mcap_path).stem


def save_blueprint(
    path: str | Path, application_id: str = APPLICATION_ID, *, series: bool = True
) -> Path:
    """Write the layout to ``path`` (an ``.rbl`` file) for ``application_id``."""
    path = Path(path)
    build_blueprint(series=series).save(application_id, str(path))
    return path
