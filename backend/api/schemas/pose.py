"""One processed frame (GET /api/pose/latest, /api/pose/history and the /ws/live
messages)."""

from __future__ import annotations

from typing import Literal

from pydantic import BaseModel, Field


class MatchedPublic(BaseModel):
    catalog_id: int
    u_px: float
    v_px: float
    point_mm: list[float] = Field(description="measured position in the camera frame")
    distance_mm: float
    residual_mm: float
    area_px: int
    centroid_sigma_px: float | None = Field(
        default=None, description="predicted 1-sigma of the centroid per image axis"
    )
    range_sigma_mm: float | None = Field(default=None, description="predicted 1-sigma of the range")
    saturated: bool = Field(
        default=False,
        description="a pixel of its blob reads at or above the camera's full scale "
        "(clipped, no distance there): lower the integration time or turn auto exposure on",
    )


class BlobPublic(BaseModel):
    u_px: float
    v_px: float
    distance_mm: float | None = Field(
        description="null when no pixel of the blob has a valid distance"
    )


RejectReason = Literal["border", "dim", "size", "oversize", "nlog", "shape", "penalty", "rank"]
"""The blob criteria's gates (``tofpose.stages.extraction.extraction.REJECT_REASONS``)."""


class RejectedBlobPublic(BaseModel):
    """A bright component of the active pixel set that is not a candidate reflector."""

    u_px: float = Field(description="centre of its bounding box")
    v_px: float
    diameter_px: float = Field(description="equivalent diameter of its area")
    reason: RejectReason
    reason_text: str = Field(description="the gate that refused it, in words")


class _ReferencePose(BaseModel):
    """The reference's pose: position, mm, and Euler angles, deg (the live pose's
    convention)."""

    x_mm: float
    y_mm: float
    z_mm: float
    pitch_deg: float
    yaw_deg: float
    roll_deg: float


class FrameReferencePublic(_ReferencePose):
    """The lab's reference for this frame (encoders + nominal geometry, or + a selected
    calibration's mount and placement) and the error of the measurement against it: the
    lab's estimate of the pose, never the truth (docs/interop.md, "Names: truth and
    reference")."""

    position_error_mm: float | None = Field(
        default=None, description="|measured - reference| of the position; null without a pose"
    )
    attitude_error_deg: float | None = Field(
        default=None, description="geodesic angle between measured and reference attitude"
    )
    label: str = Field(
        default="nominal lab geometry (uncalibrated)",
        description="which reference: the nominal lab geometry, or a calibration "
        "(PUT /api/reference)",
    )


class TruthPublic(_ReferencePose):
    """Deprecated: the older shape of ``FrameReferencePublic`` (its ``label`` was ``reference``),
    kept in ``PosePublic.truth`` for one release."""

    position_error_mm: float | None = None
    attitude_error_deg: float | None = Field(default=None, description="geodesic angle")
    reference: str = Field(
        default="nominal lab geometry (uncalibrated)",
        description="which reference: the nominal lab geometry, or a calibration "
        "(PUT /api/reference)",
    )


class PosePublic(BaseModel):
    """One processed frame. ``pitch_deg``, ``yaw_deg``, ``roll_deg`` are the attitude as
    people read it: Euler angles of ``R_camera_target @ diag(1, -1, -1)`` (a target facing
    the camera reads 0, 0, 0); ``quaternion_wxyz`` is the raw ``R_camera_target``."""

    frame_index: int
    frame_time_s: float
    captured_unix_s: float
    processed_unix_s: float
    catalog: str
    ok: bool
    reason: str
    x_mm: float | None = None
    y_mm: float | None = None
    z_mm: float | None = None
    pitch_deg: float | None = None
    yaw_deg: float | None = None
    roll_deg: float | None = None
    quaternion_wxyz: list[float] | None = None
    position_sigma_mm: list[float] | None = Field(default=None, description="1-sigma, x y z")
    attitude_sigma_deg: list[float] | None = Field(
        default=None,
        description="1-sigma of pitch, yaw and roll (deg), propagated from the rotation-"
        "vector covariance through the Euler angles' derivative (large near gimbal lock)",
    )
    n_candidates: int
    n_matched: int
    saturated_reflectors: int = Field(
        default=0, description="how many of the matched reflectors are saturated"
    )
    distances_read_about_mm: float | None = Field(
        default=None,
        description="null when the frame's distances were taken as measured; else the "
        "range (mm) they were read about, each moved by whole unambiguous ranges: the "
        "target is beyond the range the camera's distances wrap at",
    )
    pixel_fit: str | None = Field(
        default=None,
        description="null when the pose was not refined on its pixels (the server's "
        "pixel_fit setting off, or no pose); 'ok' when the pose and covariance are the "
        "pixel-level fit's; else why it fell back to the centroid pose",
    )
    matched: list[MatchedPublic]
    unmatched: list[BlobPublic]
    rejected: list[RejectedBlobPublic] = Field(
        default_factory=list, description="components refused by a gate (at most 50)"
    )
    active_threshold_counts: float | None = Field(
        default=None,
        description="I_t as applied: the active pixel set is the pixels with gray >= this",
    )
    residual_mm: float | None
    mode: Literal["acquisition", "tracking"] = Field(
        default="acquisition",
        description="acquisition: the full pass; tracking: windows around the reflectors "
        "predicted from the last pose",
    )
    iterations: int
    frames_used: int
    motion: bool
    timings_ms: dict[str, float]
    reference: FrameReferencePublic | None = Field(
        default=None,
        description="the lab's reference for this frame and the error against it; null when "
        "the source has none",
    )
    truth: TruthPublic | None = Field(
        default=None,
        deprecated=True,
        description="deprecated, removed in the next release: the same lab reference as "
        "`reference` under its older name (it never held the simulator's rendered pose)",
    )
    filter_status: Literal["initialised", "updated", "rejected", "reset", "predicted"] | None = (
        Field(
            default=None,
            description="what the relative-state filter did with this frame: started from "
            "its pose (initialised), fused it (updated), refused it as inconsistent with the "
            "motion so far (rejected), restarted after rejections that agree (reset), or "
            "predicted without a pose (predicted); null before its first pose",
        )
    )
    angular_rate_deg_s: list[float] | None = Field(
        default=None, description="the target's angular rate, camera frame (x y z), deg/s"
    )
    angular_rate_target_deg_s: list[float] | None = Field(
        default=None, description="the same rate in the target frame (x y z), deg/s"
    )
    angular_rate_sigma_deg_s: list[float] | None = Field(
        default=None, description="1-sigma of angular_rate_deg_s"
    )
    velocity_mm_s: list[float] | None = Field(
        default=None, description="the target origin's velocity, camera frame (x y z), mm/s"
    )
    velocity_sigma_mm_s: list[float] | None = Field(
        default=None, description="1-sigma of velocity_mm_s"
    )
