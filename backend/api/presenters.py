"""Presenters: build the public schemas from what the services and drivers hold.

The one place where route modules get their response objects from, so that routes do not
import each other and schemas stay plain data.
"""

from __future__ import annotations

from dataclasses import asdict
from datetime import UTC, datetime
from typing import Any, cast, overload

import numpy as np

from backend.api.schemas.calibrations import CalibrationPublic, TransformPublic
from backend.api.schemas.camera import CameraSettingsPublic
from backend.api.schemas.campaigns import (
    CampaignPublic,
    CampaignStatesPublic,
    CampaignTransitionPublic,
    MeasurementPublic,
    ProgressPublic,
    Requirements,
    SetPointPublic,
)
from backend.api.schemas.common import DeviceStatePublic, PipelineStatePublic
from backend.api.schemas.foxglove import FoxglovePublic
from backend.api.schemas.motion import AxisPublic, MotionPublic, ProfileKind, ProfilePublic
from backend.api.schemas.pose import (
    BlobPublic,
    FrameReferencePublic,
    MatchedPublic,
    PosePublic,
    RejectedBlobPublic,
    RejectReason,
    TruthPublic,
)
from backend.api.schemas.scene import ScenePublic
from backend.db.models import POSE_FIELDS, CalibrationRow, MeasurementRow
from backend.drivers.base import CameraSettings, MotionStatus
from backend.services.campaigns.campaign_repository import CampaignView
from backend.services.campaigns.campaign_states import FINISHED, CampaignState, transition_table
from backend.services.live.acquisition import LiveSample
from backend.services.live.kernel_warmup import COMPILING_REASON, REFERENCE_DETAIL
from backend.services.motion import MotionDeviceError
from backend.state import AppState
from tofpose.core.geometry import (
    RigidTransform,
    euler_deg_from_rotation,
    facing_euler_deg,
    facing_euler_sigma_deg,
    rotation_angle_deg,
)
from tofpose.core.tof import unambiguous_range_mm
from tofpose.stages.extraction.extraction import REJECT_REASONS


def _device_state(device, h) -> DeviceStatePublic:
    describe = getattr(device, "describe", None)
    info = describe() if describe is not None else {}
    return DeviceStatePublic(
        driver=device.name,
        state=h.state,
        last_error=h.last_error,
        error_count=h.error_count,
        **{k: info.get(k) for k in ("model", "firmware", "link", "address")},
    )


def camera_state(state: AppState) -> DeviceStatePublic:
    return _device_state(state.devices.camera, state.acquisition.health)


def motion_state(state: AppState) -> DeviceStatePublic:
    if not state.motion.present:
        return DeviceStatePublic(driver="none", state="absent")
    return _device_state(state.motion.driver, state.motion.health)


def pipeline_state(state: AppState) -> PipelineStatePublic:
    """Whether the live pipeline's compiled kernels are ready (backend/services/
    kernel_warmup.py) and which implementation measures the live frames: the reference
    one while they compile, the compiled one after (backend/services/live/acquisition.py)."""
    acq = state.acquisition
    kernels, implementation = acq.kernels, acq.implementation
    if kernels is None:
        return PipelineStatePublic(state="ready", implementation=implementation, seconds=0.0)
    if kernels.state == "compiling":
        detail = COMPILING_REASON if implementation is None else REFERENCE_DETAIL
    elif kernels.state == "failed":
        detail = f"{kernels.error}; poses from the reference implementation (NumPy/SciPy)"
    else:
        detail = ""
    return PipelineStatePublic(
        state=kernels.state,
        implementation=implementation,
        seconds=round(kernels.elapsed_s, 1),
        detail=detail,
    )


#: what ``motion_public`` shows when the status read fails: no positions or targets, idle
NO_READING = MotionStatus(positions={}, targets={}, busy=False, settled=True)


def motion_public(state: AppState) -> MotionPublic:
    """Axes with soft limits and the encoder read-back; a failing status read degrades
    the motion state instead of failing the request."""
    motion = state.motion
    if not motion.present:
        return MotionPublic(driver="none", state="absent")
    axes = [
        AxisPublic(
            name=a.name,
            unit=a.unit,
            min_pos=a.min_pos,
            max_pos=a.max_pos,
            max_rate_per_s=a.max_rate,
            max_accel_per_s2=a.max_accel,
        )
        for a in motion.axes.values()
    ]
    owner = motion.owner
    latched_at = motion.stop_latched_at
    try:
        st = motion.status()
    except MotionDeviceError:  # the device state says why; nothing was read
        st = NO_READING
    p = st.profile
    profile = (
        None
        if p is None
        else ProfilePublic(
            axis=p.axis,
            kind=cast(ProfileKind, p.kind),  # a driver's profile kind; pydantic checks it
            elapsed_s=p.elapsed_s,
            remaining_s=p.remaining_s,
            duration_s=p.duration_s,
        )
    )
    return MotionPublic(
        **motion_state(state).model_dump(),  # after the status read, which sets the health
        axes=axes,
        positions=st.positions,
        time_s=st.time_s,
        targets=st.targets,
        busy=st.busy,
        settled=st.settled,
        stopped=st.stopped,
        profile=profile,
        owner_campaign_id=owner.campaign_id if owner else None,
        owner_campaign_name=owner.name if owner else None,
        stop_latched=latched_at is not None,
        stop_latched_at=latched_at.isoformat() if latched_at else None,
    )


def camera_settings_public(
    s: CameraSettings, *, locked: str | None = None, frequency_held: str | None = None
) -> CameraSettingsPublic:
    return CameraSettingsPublic(
        **asdict(s),
        unambiguous_range_mm=unambiguous_range_mm(s.modulation_frequency_mhz),
        locked=locked,
        frequency_held=frequency_held,
    )


def finite_or_none(value: float) -> float | None:
    """JSON has no NaN/inf: a value the pipeline could not compute is sent as null."""
    v = float(value)
    return v if np.isfinite(v) else None


def finite_list_or_none(values) -> list[float] | None:
    """A vector is sent only when every component is finite, else null."""
    out = [float(v) for v in values]
    return out if all(np.isfinite(out)) else None


MAX_REJECTED_SHOWN = 50  # a cluttered frame must not make every pose message huge


def pose_from_sample(s: LiveSample) -> PosePublic:
    """The public form of one processed frame; values that are not finite become null."""
    r = s.result
    pose: dict[str, Any] = {}
    if (
        r.ok
        and r.R is not None
        and r.t_mm is not None
        and r.euler_deg is not None
        and r.quaternion_wxyz is not None
    ):
        x, y, z = (float(v) for v in r.t_mm)
        p, yw, rl = (float(v) for v in r.euler_deg)
        pose = dict(x_mm=x, y_mm=y, z_mm=z, pitch_deg=p, yaw_deg=yw, roll_deg=rl)
        pose["quaternion_wxyz"] = [float(v) for v in r.quaternion_wxyz]
        if r.covariance is not None:
            sd = np.sqrt(np.clip(np.diag(r.covariance), 0.0, None))
            pose["attitude_sigma_deg"] = finite_list_or_none(
                facing_euler_sigma_deg(r.R, r.covariance)
            )
            pose["position_sigma_mm"] = finite_list_or_none(sd[3:])
    if s.state is not None:
        st = s.state
        pose["filter_status"] = st.status
        pose["angular_rate_deg_s"] = finite_list_or_none(st.angular_rate_deg_s)
        pose["angular_rate_target_deg_s"] = finite_list_or_none(st.angular_rate_target_deg_s)
        pose["angular_rate_sigma_deg_s"] = finite_list_or_none(st.angular_rate_sigma_deg_s)
        pose["velocity_mm_s"] = finite_list_or_none(st.velocity_mm_s)
        pose["velocity_sigma_mm_s"] = finite_list_or_none(st.velocity_sigma_mm_s)
    reference = truth = None
    T = s.reference.pose(s.frame)
    if T is not None:
        reference = _reference(
            T, r.R if r.ok else None, r.t_mm if r.ok else None, s.reference.label
        )
        truth = TruthPublic(  # the deprecated older name, the same values
            **reference.model_dump(exclude={"label"}), reference=reference.label
        )
    return PosePublic(
        frame_index=s.frame.index,
        frame_time_s=s.frame.time_s,
        captured_unix_s=s.captured_unix_s,
        processed_unix_s=s.processed_unix_s,
        catalog=s.catalog_name,
        ok=r.ok,
        reason=r.reason,
        mode=r.mode,
        n_candidates=r.n_candidates,
        n_matched=r.n_matched,
        saturated_reflectors=sum(m.saturated for m in r.matched),
        distances_read_about_mm=None
        if r.distances_read_about_mm is None
        else float(r.distances_read_about_mm),
        pixel_fit=r.pixel_fit or None,
        matched=[
            MatchedPublic(
                catalog_id=m.catalog_id,
                u_px=float(m.centroid_uv[0]),
                v_px=float(m.centroid_uv[1]),
                point_mm=[float(v) for v in m.point_mm],
                distance_mm=float(m.distance_mm),
                residual_mm=float(m.residual_mm),
                area_px=int(m.area_px),
                centroid_sigma_px=finite_or_none(m.centroid_sigma_px),
                range_sigma_mm=finite_or_none(m.range_sigma_mm),
                saturated=bool(m.saturated),
            )
            for m in r.matched
        ],
        unmatched=[
            BlobPublic(u_px=float(u), v_px=float(v), distance_mm=finite_or_none(d))
            for u, v, d in r.unmatched
        ],
        rejected=[
            RejectedBlobPublic(
                u_px=float(b.u_px),
                v_px=float(b.v_px),
                diameter_px=float(b.diameter_px),
                reason=cast(RejectReason, b.reason),  # one of REJECT_REASONS; pydantic checks it
                reason_text=REJECT_REASONS[b.reason],
            )
            for b in r.rejected[:MAX_REJECTED_SHOWN]
        ],
        active_threshold_counts=finite_or_none(r.active_threshold_counts),
        residual_mm=finite_or_none(r.residual_mm),
        iterations=r.iterations,
        frames_used=r.frames_used,
        motion=r.motion,
        timings_ms={k: float(v) for k, v in r.timings_ms.items()},
        reference=reference,
        truth=truth,
        **pose,
    )


def pose_public(sample: LiveSample) -> PosePublic:
    """The sample's ``PosePublic``, built once and shared by REST and WebSocket."""
    return sample.cached("pose_public", lambda: pose_from_sample(sample))


def _reference(
    T: RigidTransform, R: np.ndarray | None, t_mm: np.ndarray | None, label: str
) -> FrameReferencePublic:
    """The lab's reference pose ``T`` and the error of the measured ``R``, ``t_mm`` (None
    without a pose) against it; ``label`` names the reference."""
    p, y, r = (float(v) for v in facing_euler_deg(T.R))
    err_pos = err_ang = None
    if R is not None and t_mm is not None:
        err_pos = float(np.linalg.norm(np.asarray(t_mm) - T.t_mm))
        err_ang = float(rotation_angle_deg(T.R, R))
    x, yy, z = (float(v) for v in T.t_mm)
    return FrameReferencePublic(
        x_mm=x,
        y_mm=yy,
        z_mm=z,
        pitch_deg=p,
        yaw_deg=y,
        roll_deg=r,
        position_error_mm=err_pos,
        attitude_error_deg=err_ang,
        label=label,
    )


def campaign_public(
    c: CampaignView,
    progress: dict | None,
    estimated_duration_s: float,
    *,
    with_setpoints: bool = False,
) -> CampaignPublic:
    return CampaignPublic(
        id=c.id,
        name=c.name,
        status=c.status,
        status_reason=c.status_reason,
        catalog=c.catalog,
        frames_per_point=c.frames_per_point,
        settle_s=c.settle_s,
        lock_timeout_s=c.lock_timeout_s,
        requirements=Requirements(**c.requirements),
        generator=c.generator,
        camera=c.camera,
        camera_sweep=c.camera_sweep,
        operator=c.operator,
        target_name=c.target_name,
        camera_model=c.camera_model,
        camera_serial=c.camera_serial,
        camera_firmware=c.camera_firmware,
        record_raw=c.record_raw,
        notes=c.notes,
        created_at=as_utc(c.created_at),
        scheduled_at=as_utc(c.scheduled_at),
        started_at=as_utc(c.started_at),
        finished_at=as_utc(c.finished_at),
        n_setpoints=len(c.setpoints),
        n_done=c.n_done,
        estimated_duration_s=estimated_duration_s,
        progress=ProgressPublic(**progress) if progress else None,
        setpoints=[
            SetPointPublic(
                index=sp.index,
                yaw_deg=sp.yaw_deg,
                pitch_deg=sp.pitch_deg,
                roll_deg=sp.roll_deg,
                rail_mm=sp.rail_mm,
                profile=sp.profile,
                camera=sp.camera,
                status=sp.status,
            )
            for sp in c.setpoints
        ]
        if with_setpoints
        else None,
    )


def campaign_states_public() -> CampaignStatesPublic:
    """The campaign state machine (``backend.services.campaigns.campaign_states``)."""
    return CampaignStatesPublic(
        states=list(CampaignState),
        finished=[s for s in CampaignState if s in FINISHED],
        transitions=[
            CampaignTransitionPublic(from_state=a, command=c, to_state=b)
            for a, c, b in transition_table()
        ],
    )


@overload
def as_utc(dt: datetime) -> datetime: ...
@overload
def as_utc(dt: None) -> None: ...
def as_utc(dt: datetime | None) -> datetime | None:
    """Stored times are UTC; SQLite hands them back without a zone."""
    return dt.replace(tzinfo=UTC) if dt is not None and dt.tzinfo is None else dt


def _pose_dict(m: MeasurementRow, prefix: str) -> dict[str, float] | None:
    values = {k: getattr(m, prefix + k) for k in POSE_FIELDS}
    return values if all(v is not None for v in values.values()) else None


def measurement_public(m: MeasurementRow, setpoint_index: int) -> MeasurementPublic:
    return MeasurementPublic(
        setpoint_index=setpoint_index,
        frame_index=m.frame_index,
        time_s=m.frame_time_s,
        ok=m.ok,
        reason=m.reason,
        n_matched=m.n_matched,
        residual_mm=m.residual_mm,
        x_mm=m.x_mm,
        y_mm=m.y_mm,
        z_mm=m.z_mm,
        pitch_deg=m.pitch_deg,
        yaw_deg=m.yaw_deg,
        roll_deg=m.roll_deg,
        truth=_pose_dict(m, "truth_"),
        reference=_pose_dict(m, "lab_truth_"),  # the database keeps the older column names
        lab_truth=_pose_dict(m, "lab_truth_"),
        encoders=m.encoders,
        integration_time_us=m.integration_time_us,
        pixel_fit=m.pixel_fit,
        in_motion=m.in_motion,
    )


def _transform_public(matrix: list[list[float]]) -> TransformPublic:
    M = np.asarray(matrix, float)
    return TransformPublic(
        matrix=M.tolist(),
        euler_deg=[float(v) for v in euler_deg_from_rotation(M[:3, :3])],
        translation_mm=[float(v) for v in M[:3, 3]],
    )


def calibration_public(row: CalibrationRow) -> CalibrationPublic:
    s = row.sigmas
    return CalibrationPublic(
        id=row.id,
        name=row.name,
        campaign_id=row.campaign_id,
        created_at=as_utc(row.created_at),
        mount=_transform_public(row.mount),
        placement=_transform_public(row.placement),
        mount_sigma_deg=s[0:3],
        mount_sigma_mm=s[3:6],
        placement_sigma_deg=s[6:9],
        placement_sigma_mm=s[9:12],
        residual_rms_mm=float(np.sqrt(np.mean(np.square(row.residual_mm)))),
        residual_rms_deg=float(np.sqrt(np.mean(np.square(row.residual_deg)))),
        chi2_per_dof=row.chi2_per_dof,
        n_observations=row.n_observations,
    )


def foxglove_public(state: AppState) -> FoxglovePublic:
    fox = state.foxglove
    if fox is None:
        return FoxglovePublic(running=False, reason=state.foxglove_reason)
    return FoxglovePublic(
        running=True,
        url=fox.url,
        port=fox.port,
        subprotocols=list(fox.subprotocols),
        published=fox.published,
        dropped=fox.dropped,
    )


def scene_public(state: AppState) -> ScenePublic:
    scene = state.scene
    if scene is None:
        return ScenePublic(running=False, reason=state.scene_reason)
    return ScenePublic(
        running=True,
        port=scene.port,
        paused=scene.paused,
        updates=scene.updates,
        last_frame_index=scene.last_frame_index,
    )
