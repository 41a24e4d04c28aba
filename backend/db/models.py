"""SQLAlchemy 2 models. Alembic migrations in ``migrations/`` create exactly these
(tests/backend/db/test_migrations.py compares them).

Units are in the column names (docs/architecture.md §3): mm, deg, s.
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    pass


class DeviceSettingsRow(Base):
    """Last applied settings of a device (``camera``, ``pipeline``), re-applied at start."""

    __tablename__ = "device_settings"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    device: Mapped[str] = mapped_column(String(64), unique=True)
    settings: Mapped[dict[str, Any]] = mapped_column(JSON)
    updated_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class CatalogRow(Base):
    """A user-supplied target catalog (the built-in ones live in ``tofpose.core.catalog``)."""

    __tablename__ = "catalogs"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(128), unique=True)
    catalog_json: Mapped[str] = mapped_column(Text)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


POSE_FIELDS = ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg")


class CampaignRow(Base):
    """A turntable test campaign: a set-point sequence measured N frames per point.

    status : a ``backend.services.campaigns.campaign_states.CampaignState`` (docs/campaigns.md has
        the state diagram; that module has the transition table).
    settle_s : wait after the turntable reports settled before frames count (device time).
    requirements : per-axis accuracy requirements, e.g. {"x_mm": 6.0, ..., "roll_deg": 0.15}.
    generator : the generator request the set-points came from, or None for explicit ones.
    status_reason : why the campaign is paused / failed / interrupted.
    camera_settings : settings applied before the first set-point (under each set-point's own).
    camera_sweep : the sweep the set-points' camera settings came from, e.g.
        {"integration_time_us": [250, 500, 1000]}, or None.
    operator, target_name : who ran it and the target measured (free text).
    camera_model, camera_serial, camera_firmware : the camera, read from the device where
        its driver reports them, else as given when the campaign was created.
    """

    __tablename__ = "campaigns"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    status: Mapped[str] = mapped_column(String(16), default="draft", index=True)
    status_reason: Mapped[str] = mapped_column(Text, default="")
    catalog_name: Mapped[str] = mapped_column(String(128))
    frames_per_point: Mapped[int] = mapped_column(Integer, default=30)
    settle_s: Mapped[float] = mapped_column(Float, default=1.0)
    lock_timeout_s: Mapped[float] = mapped_column(Float, default=5.0)
    requirements: Mapped[dict[str, float]] = mapped_column(JSON)
    generator: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    camera_settings: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    camera_sweep: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    operator: Mapped[str] = mapped_column(String(200), default="", server_default="")
    target_name: Mapped[str] = mapped_column(String(200), default="", server_default="")
    camera_model: Mapped[str] = mapped_column(String(200), default="", server_default="")
    camera_serial: Mapped[str] = mapped_column(String(200), default="", server_default="")
    camera_firmware: Mapped[str] = mapped_column(String(200), default="", server_default="")
    record_raw: Mapped[bool] = mapped_column(Boolean, default=False)
    recording_path: Mapped[str | None] = mapped_column(Text, nullable=True)
    notes: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    scheduled_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)

    setpoints: Mapped[list[SetPointRow]] = relationship(
        back_populates="campaign", cascade="all, delete-orphan", order_by="SetPointRow.index"
    )


class SetPointRow(Base):
    """One set-point of a campaign; None for an axis means "leave it where it is".

    status : pending or done. A set-point becomes done in the same transaction that
    stores its measurements, so a crash never leaves half a set-point counted.
    profile : a dynamic set-point's motion profile (``axis``, ``kind`` and its fields, as
    POST /api/motion/profile takes them), run from the set-point after a rest; None at a
    static one.
    camera : camera settings applied before the set-point's frames
    ({"integration_time_us": .., "modulation_frequency_mhz": ..}, either may be absent),
    or None (the camera as it is).
    """

    __tablename__ = "setpoints"
    __table_args__ = (UniqueConstraint("campaign_id", "index", name="uq_setpoint_index"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    campaign_id: Mapped[int] = mapped_column(ForeignKey("campaigns.id", ondelete="CASCADE"))
    index: Mapped[int] = mapped_column(Integer)
    yaw_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    pitch_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    roll_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    rail_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    profile: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    camera: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    status: Mapped[str] = mapped_column(String(16), default="pending")
    completed_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)

    campaign: Mapped[CampaignRow] = relationship(back_populates="setpoints")
    measurements: Mapped[list[MeasurementRow]] = relationship(
        back_populates="setpoint", cascade="all, delete-orphan", order_by="MeasurementRow.id"
    )


class MeasurementRow(Base):
    """One frame measured at a set-point.

    Pose: position mm, attitude as people read it (facing Euler, docs/architecture.md §3),
    raw quaternion of R_camera_target, the pipeline's own 1-sigma (position per axis;
    attitude as the rotation-vector components about camera x, y, z, which near face-on
    are the pitch, yaw and roll sigmas). ``truth_*``: the pose
    that produced the frame when the source knows it (simulator, a replayed recording's
    ``/truth``: ``CameraFrame.T_camera_target_exact``); ``lab_truth_*``: what the lab
    computes from the encoders and the nominal geometry (or a replayed recording's
    ``/lab_truth``: ``CameraFrame.T_camera_target_lab``). ``encoders``: axis
    read-back at capture (deg / mm). ``recording_index``: frame number in the campaign's
    raw recording, when one is kept. ``rate_*``, ``vel_*``, ``sigma_rate_*``,
    ``sigma_vel_*``, ``filter_status``: the relative-state filter's state at the frame
    (null before its first pose). ``in_motion``: taken while the set-point's motion
    profile ran (null at a set-point without one; ``encoders`` and ``lab_truth_*`` of a
    profile set-point are interpolated to the frame's capture time).
    ``integration_time_us``: the exposure the frame was taken with, as the camera reports
    it per frame (null when it does not). ``pixel_fit``: "ok" when the pose and sigmas are
    the pixel-level fit's (the server's ``pixel_fit`` setting), else why the centroid pose
    stands; null when the fit did not run.
    """

    __tablename__ = "measurements"
    __table_args__ = (UniqueConstraint("setpoint_id", "frame_index", name="uq_measurement_frame"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    setpoint_id: Mapped[int] = mapped_column(
        ForeignKey("setpoints.id", ondelete="CASCADE"), index=True
    )
    frame_index: Mapped[int] = mapped_column(Integer)
    frame_time_s: Mapped[float] = mapped_column(Float)
    ok: Mapped[bool] = mapped_column(Boolean)
    reason: Mapped[str] = mapped_column(Text, default="")
    n_matched: Mapped[int] = mapped_column(Integer, default=0)
    residual_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    x_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    y_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    z_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    pitch_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    yaw_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    roll_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    qw: Mapped[float | None] = mapped_column(Float, nullable=True)
    qx: Mapped[float | None] = mapped_column(Float, nullable=True)
    qy: Mapped[float | None] = mapped_column(Float, nullable=True)
    qz: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_x_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_y_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_z_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_pitch_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_yaw_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_roll_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_x_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_y_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_z_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_pitch_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_yaw_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    truth_roll_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_x_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_y_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_z_mm: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_pitch_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_yaw_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    lab_truth_roll_deg: Mapped[float | None] = mapped_column(Float, nullable=True)
    encoders: Mapped[dict[str, float] | None] = mapped_column(JSON, nullable=True)
    recording_index: Mapped[int | None] = mapped_column(Integer, nullable=True)
    # the relative-state filter at the frame (tofpose.lab.relative_state): angular rate deg/s
    # and velocity mm/s in the camera frame, their 1-sigma, and what it did with the pose
    rate_x_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    rate_y_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    rate_z_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    vel_x_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    vel_y_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    vel_z_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_rate_x_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_rate_y_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_rate_z_deg_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_vel_x_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_vel_y_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    sigma_vel_z_mm_s: Mapped[float | None] = mapped_column(Float, nullable=True)
    filter_status: Mapped[str | None] = mapped_column(String(16), nullable=True)
    in_motion: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    integration_time_us: Mapped[float | None] = mapped_column(Float, nullable=True)
    pixel_fit: Mapped[str | None] = mapped_column(Text, nullable=True)

    setpoint: Mapped[SetPointRow] = relationship(back_populates="measurements")


class CalibrationRow(Base):
    """A bench calibration estimated from a campaign: the camera's installation on the
    inner axis (``mount``) and the target's placement in the lab (``placement``), each a
    4 x 4 homogeneous matrix (mm), with 1-sigma (mount rotation xyz deg, translation xyz
    mm, placement rotation xyz deg, translation xyz mm) and the fit's residuals."""

    __tablename__ = "calibrations"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    campaign_id: Mapped[int | None] = mapped_column(
        ForeignKey("campaigns.id", ondelete="SET NULL"), nullable=True
    )
    mount: Mapped[list[list[float]]] = mapped_column(JSON)
    placement: Mapped[list[list[float]]] = mapped_column(JSON)
    sigmas: Mapped[list[float]] = mapped_column(JSON)
    residual_mm: Mapped[list[float]] = mapped_column(JSON)
    residual_deg: Mapped[list[float]] = mapped_column(JSON)
    chi2_per_dof: Mapped[float] = mapped_column(Float)
    n_observations: Mapped[int] = mapped_column(Integer)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ApiKeyRow(Base):
    """An API key (backend/services/keys.py): its name, scope (read, operate or admin)
    and the SHA-256 of the key (hex). The key itself is never stored. A revoked key keeps
    its row (``revoked_at`` set) and its name, so that the audit trail's key names keep
    naming one key."""

    __tablename__ = "api_keys"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    name: Mapped[str] = mapped_column(String(64), unique=True)
    scope: Mapped[str] = mapped_column(String(16))
    key_sha256: Mapped[str] = mapped_column(String(64), unique=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    revoked_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)


class AuditRow(Base):
    """One state-changing request (POST, PUT, PATCH, DELETE), answered or refused: when
    (UTC), by which key (None: no valid key), from which client address, what (method,
    path, a redacted summary of the JSON body) and the HTTP status answered."""

    __tablename__ = "audit_log"

    id: Mapped[int] = mapped_column(Integer, primary_key=True)
    at: Mapped[datetime] = mapped_column(DateTime(timezone=True))
    key_name: Mapped[str | None] = mapped_column(String(64), nullable=True)
    client: Mapped[str] = mapped_column(String(64), default="")
    method: Mapped[str] = mapped_column(String(8))
    path: Mapped[str] = mapped_column(Text)
    body: Mapped[str] = mapped_column(Text, default="")
    status: Mapped[int] = mapped_column(Integer)
