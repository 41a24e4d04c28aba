"""Campaigns in the database, and their raw HDF5 recording kept in step with it.

Every query on campaigns, set-points and measurements that the campaign service and the
routes make is here; what leaves is plain data (``CampaignView``, ``SetPointView``) read
in one session, so no caller holds a session or a row that loads lazily. A state change
asked for by a person goes through ``check_transition`` (``campaign_states``).

A set-point's frames and its ``done`` mark are committed in one transaction
(``store_setpoint``), and ``RawRecorder`` keeps the recording's ``/frames`` equal to the
committed measurements (docs/campaigns.md, "What counts as a measurement").
"""

from __future__ import annotations

import builtins
from collections.abc import Iterable
from dataclasses import dataclass, fields
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session, selectinload, sessionmaker

from backend.db.models import CampaignRow, MeasurementRow, SetPointRow, utcnow
from backend.services.campaigns.campaign_recording import CampaignRecordingWriter
from backend.services.campaigns.campaign_states import (
    FINISHED,
    RUNNER_TRANSITIONS,
    CampaignCommand,
    CampaignState,
    check_transition,
)
from backend.services.live.acquisition import LiveSample
from backend.services.store import commit_unique
from tofpose.core.geometry import RigidTransform, facing_euler_deg, facing_euler_sigma_deg

AXIS_COLUMNS = {"yaw": "yaw_deg", "pitch": "pitch_deg", "roll": "roll_deg", "rail": "rail_mm"}


class CampaignNotFoundError(LookupError):
    """No campaign with this id."""


@dataclass(frozen=True)
class SetPointView:
    """One stored set-point: None for an axis means "leave it where it is"."""

    id: int
    index: int
    yaw_deg: float | None
    pitch_deg: float | None
    roll_deg: float | None
    rail_mm: float | None
    profile: dict | None
    camera: dict | None
    status: Literal["pending", "done"]

    @property
    def axes(self) -> dict[str, float]:
        """{axis: deg / mm} of the axes this set-point moves."""
        return {
            a: float(getattr(self, c))
            for a, c in AXIS_COLUMNS.items()
            if getattr(self, c) is not None
        }


@dataclass(frozen=True)
class CampaignView:
    """A stored campaign with its set-points in index order (``backend.db.models``
    describes each field). Its fields have the API's names (``CampaignPublic``), so
    that the presenter copies them as they are; the row's columns that are named
    otherwise are listed in ``_ROW_COLUMNS``."""

    id: int
    name: str
    status: CampaignState
    status_reason: str
    catalog: str
    frames_per_point: int
    settle_s: float
    lock_timeout_s: float
    requirements: dict[str, float]
    generator: dict | None
    camera: dict | None
    camera_sweep: dict | None
    operator: str
    target_name: str
    camera_model: str
    camera_serial: str
    camera_firmware: str
    record_raw: bool
    notes: str
    created_at: datetime
    scheduled_at: datetime | None
    started_at: datetime | None
    finished_at: datetime | None
    setpoints: tuple[SetPointView, ...]

    @property
    def pending(self) -> list[SetPointView]:
        """The set-points not done yet: what a run (or a resume) measures."""
        return [sp for sp in self.setpoints if sp.status != "done"]

    @property
    def n_done(self) -> int:
        return len(self.setpoints) - len(self.pending)


_SETPOINT_FIELDS = [f.name for f in fields(SetPointView)]
_CAMPAIGN_FIELDS = [f.name for f in fields(CampaignView) if f.name not in ("status", "setpoints")]
#: the view's fields that the row's columns name otherwise (view field -> column)
_ROW_COLUMNS = {"catalog": "catalog_name", "camera": "camera_settings"}


def _utc(value):
    """Stored times are UTC; SQLite hands them back without a zone."""
    if isinstance(value, datetime) and value.tzinfo is None:
        return value.replace(tzinfo=UTC)
    return value


def _view(row: CampaignRow) -> CampaignView:
    setpoints = tuple(
        SetPointView(**{k: getattr(sp, k) for k in _SETPOINT_FIELDS}) for sp in row.setpoints
    )
    return CampaignView(
        status=CampaignState(row.status),
        setpoints=setpoints,
        **{k: _utc(getattr(row, _ROW_COLUMNS.get(k, k))) for k in _CAMPAIGN_FIELDS},
    )


def create_campaign(
    s: Session,
    *,
    name: str,
    catalog_name: str,
    setpoints: list[dict[str, float]],
    frames_per_point: int,
    settle_s: float,
    lock_timeout_s: float,
    requirements: dict[str, float],
    generator: dict | None = None,
    camera: dict | None = None,
    notes: str = "",
    record_raw: bool = False,
    profiles: list[dict | None] | None = None,
    cameras: list[dict | None] | None = None,
    camera_sweep: dict | None = None,
    metadata: dict[str, str] | None = None,
) -> CampaignRow:
    """Store a draft campaign with its set-points (and, for a dynamic one, the motion
    profile of each; ``cameras``: each one's camera settings) in session ``s``;
    ``metadata``: ``operator``, ``target_name``, ``camera_model``, ``camera_serial``,
    ``camera_firmware``. ``NameTakenError`` if the name exists."""
    row = CampaignRow(
        name=name,
        status=CampaignState.DRAFT.value,
        status_reason="",
        catalog_name=catalog_name,
        frames_per_point=frames_per_point,
        settle_s=settle_s,
        lock_timeout_s=lock_timeout_s,
        requirements=requirements,
        generator=generator,
        camera_settings=camera,
        notes=notes,
        record_raw=record_raw,
        camera_sweep=camera_sweep,
        **(metadata or {}),
    )
    for i, sp in enumerate(setpoints):
        row.setpoints.append(
            SetPointRow(
                index=i,
                status="pending",
                profile=profiles[i] if profiles else None,
                camera=(cameras[i] or None) if cameras else None,
                **{AXIS_COLUMNS[a]: float(v) for a, v in sp.items()},
            )
        )
    s.add(row)
    commit_unique(s, f"a campaign named {name!r}")
    return row


class CampaignRepository:
    """The campaign tables through a session factory; each method is one session (and,
    where it writes, one transaction)."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self.sessions = sessions

    @staticmethod
    def _row(s: Session, campaign_id: int, *, for_update: bool = False) -> CampaignRow:
        row = s.get(CampaignRow, campaign_id, with_for_update=True if for_update else None)
        if row is None:
            raise CampaignNotFoundError(f"no campaign with id {campaign_id}")
        return row

    # -- reading ----------------------------------------------------------------------------
    def get(self, campaign_id: int) -> CampaignView:
        """The campaign; ``CampaignNotFoundError`` if there is none with this id."""
        with self.sessions() as s:
            return _view(self._row(s, campaign_id))

    def exists(self, campaign_id: int) -> bool:
        with self.sessions() as s:
            return s.get(CampaignRow, campaign_id) is not None

    def list(self) -> list[CampaignView]:
        """Every campaign, newest first."""
        with self.sessions() as s:
            rows = s.scalars(
                select(CampaignRow)
                .options(selectinload(CampaignRow.setpoints))
                .order_by(CampaignRow.id.desc())
            ).all()
            return [_view(r) for r in rows]

    def measurements(
        self, campaign_id: int, offset: int, limit: int
    ) -> tuple[int, builtins.list[tuple[MeasurementRow, int]]]:
        """(total, a page of (measurement, set-point index)) in set-point then frame order;
        ``CampaignNotFoundError`` for an unknown campaign."""
        with self.sessions() as s:
            self._row(s, campaign_id)
            base = (
                select(MeasurementRow, SetPointRow.index)
                .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
                .where(SetPointRow.campaign_id == campaign_id)
            )
            total = s.scalar(select(func.count()).select_from(base.subquery())) or 0
            rows = s.execute(
                base.order_by(SetPointRow.index, MeasurementRow.id).offset(offset).limit(limit)
            ).all()
            return total, [(m, i) for m, i in rows]

    def committed_frames(self, campaign_id: int) -> int:
        """Measurements stored for the campaign (= frames its recording should hold)."""
        with self.sessions() as s:
            count = s.scalar(
                select(func.count())
                .select_from(MeasurementRow)
                .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
                .where(SetPointRow.campaign_id == campaign_id)
            )
            return count or 0

    def next_due(self, now: datetime) -> int | None:
        """The queued campaign to run next: unscheduled ones first (by id), then those
        whose start time has come, earliest first."""
        with self.sessions() as s:
            rows = s.scalars(
                select(CampaignRow)
                .where(CampaignRow.status == CampaignState.QUEUED.value)
                .order_by(
                    CampaignRow.scheduled_at.is_not(None), CampaignRow.scheduled_at, CampaignRow.id
                )
            ).all()
            for row in rows:
                at = _utc(row.scheduled_at)
                if at is None or at <= now:
                    return row.id
        return None

    # -- writing ----------------------------------------------------------------------------
    def create(self, **campaign: Any) -> CampaignView:
        """``create_campaign`` in a session of its own."""
        with self.sessions() as s:
            return _view(create_campaign(s, **campaign))

    def apply(
        self,
        campaign_id: int,
        command: CampaignCommand,
        *,
        reason: str = "",
        scheduled_at: datetime | None = None,
    ) -> CampaignState:
        """A person's ``command`` on the stored campaign, checked against
        ``TRANSITIONS`` (``CampaignTransitionError``); ``scheduled_at`` is set by start
        and resume. Returns the new state."""
        with self.sessions() as s, s.begin():
            row = self._row(s, campaign_id)
            to = check_transition(row.status, command, campaign_id)
            row.status, row.status_reason = to.value, reason
            if command in (CampaignCommand.START, CampaignCommand.RESUME):
                row.scheduled_at = scheduled_at
            if to in FINISHED:
                row.finished_at = utcnow()
            return to

    def set_status(self, campaign_id: int, status: CampaignState, reason: str = "") -> bool:
        """The runner's state changes, with the times they mark: only those
        ``RUNNER_TRANSITIONS`` allows from the stored state (the row is locked while it is
        read and written), so a campaign a person paused or cancelled after the scheduler
        picked it is never taken back to running. Returns whether the state changed."""
        with self.sessions() as s, s.begin():
            row = self._row(s, campaign_id, for_update=True)
            if status not in RUNNER_TRANSITIONS.get(CampaignState(row.status), frozenset()):
                return False
            row.status, row.status_reason = status.value, reason
            if status is CampaignState.RUNNING and row.started_at is None:
                row.started_at = utcnow()
            if status in FINISHED:
                row.finished_at = utcnow()
            return True

    def recover(self, now: datetime | None = None) -> tuple[int, int]:
        """At start: campaigns left running by a server that died are interrupted, and
        queued ones (scheduled or not) are paused, so that nothing moves the table until
        a person resumes them. Returns (interrupted, held)."""
        when = f"{(now or datetime.now(UTC)):%Y-%m-%d %H:%M:%S} UTC"
        with self.sessions() as s, s.begin():
            running = s.scalars(
                select(CampaignRow).where(CampaignRow.status == CampaignState.RUNNING.value)
            ).all()
            for row in running:
                row.status = CampaignState.INTERRUPTED.value
                row.status_reason = (
                    f"the server stopped while this campaign was running "
                    f"(restarted {when}): resume it to continue"
                )
            queued = s.scalars(
                select(CampaignRow).where(CampaignRow.status == CampaignState.QUEUED.value)
            ).all()
            for row in queued:
                row.status = CampaignState.PAUSED.value
                row.status_reason = (
                    f"held at server start ({when}): nothing moves after a "
                    "restart until a person resumes it"
                )
            return len(running), len(queued)

    def store_setpoint(
        self,
        setpoint_id: int,
        frames: Iterable[tuple[LiveSample, bool | None]],
        first_recording_index: int | None = None,
    ) -> None:
        """The set-point's frames (with whether a profile ran at each) and its ``done``
        mark, in one transaction; ``first_recording_index``: where the first of them is
        in the campaign's raw recording, None without one."""
        with self.sessions() as s, s.begin():
            for k, (sample, in_motion) in enumerate(frames):
                m = measurement_row(setpoint_id, sample)
                m.in_motion = in_motion
                if first_recording_index is not None:
                    m.recording_index = first_recording_index + k
                s.add(m)
            sp = s.get_one(SetPointRow, setpoint_id)
            sp.status, sp.completed_at = "done", utcnow()


def measurement_row(setpoint_id: int, sample: LiveSample) -> MeasurementRow:
    """One stored frame: pose (facing Euler), sigmas, exact truth (``truth_*``, from the
    frame's ``T_camera_target_exact``) and the lab's reference (``lab_truth_*``, from
    ``T_camera_target_lab``), encoders, the relative-state filter's rates and velocity
    with their sigmas, and whether the pose is the pixel-level fit's (``pixel_fit``)."""
    r, f = sample.result, sample.frame
    row = MeasurementRow(
        setpoint_id=setpoint_id,
        frame_index=f.index,
        frame_time_s=float(f.time_s),
        ok=bool(r.ok),
        reason=r.reason,
        n_matched=int(r.n_matched),
        residual_mm=_finite(r.residual_mm),
        encoders={k: float(v) for k, v in f.meta.get("encoders", {}).items()} or None,
        integration_time_us=_reported_us(f.meta.get("integration_time_us")),
        pixel_fit=r.pixel_fit or None,
    )
    if r.ok and r.R is not None and r.t_mm is not None and r.quaternion_wxyz is not None:
        row.x_mm, row.y_mm, row.z_mm = (float(v) for v in r.t_mm)
        row.pitch_deg, row.yaw_deg, row.roll_deg = (float(v) for v in facing_euler_deg(r.R))
        row.qw, row.qx, row.qy, row.qz = (float(v) for v in r.quaternion_wxyz)
        if r.covariance is not None:
            sd = np.sqrt(np.clip(np.diag(r.covariance), 0.0, None))
            row.sigma_pitch_deg, row.sigma_yaw_deg, row.sigma_roll_deg = (
                _finite(v) for v in facing_euler_sigma_deg(r.R, r.covariance)
            )
            row.sigma_x_mm, row.sigma_y_mm, row.sigma_z_mm = (_finite(v) for v in sd[3:])
    st = sample.state
    if st is not None:
        row.filter_status = st.status
        for name, values in (
            ("rate_{}_deg_s", st.angular_rate_deg_s),
            ("vel_{}_mm_s", st.velocity_mm_s),
            ("sigma_rate_{}_deg_s", st.angular_rate_sigma_deg_s),
            ("sigma_vel_{}_mm_s", st.velocity_sigma_mm_s),
        ):
            for axis, v in zip("xyz", values, strict=True):
                setattr(row, name.format(axis), _finite(v))
    _set_reference(row, "truth_", f.T_camera_target_exact)
    _set_reference(row, "lab_truth_", f.T_camera_target_lab)
    return row


def _set_reference(row: MeasurementRow, prefix: str, T: RigidTransform | None) -> None:
    """Fill ``row``'s ``prefix``-named pose columns (mm; facing Euler, deg) from ``T``
    (``T_camera_target``); leave them null when ``T`` is None."""
    if T is None:
        return
    p, y, rl = (float(v) for v in facing_euler_deg(T.R))
    x, yy, z = (float(v) for v in T.t_mm)
    for name, v in zip(
        ("x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg"),
        (x, yy, z, p, y, rl),
        strict=True,
    ):
        setattr(row, prefix + name, v)


def _reported_us(v) -> float | None:
    """A frame's reported integration time (us), None when the camera gives none."""
    return None if v is None else _finite(v)


def _finite(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


class RawRecordingError(RuntimeError):
    """A frame that cannot go into a campaign's raw recording (the runner pauses the
    campaign with this reason)."""


class RawRecorder:
    """A campaign's raw frames in an HDF5 recording (docs/architecture.md §7), kept equal
    to what the database holds: frames are appended as they are measured, the file is
    flushed before the set-point's transaction commits, and frames of a set-point that
    did not complete (pause, cancel, shutdown; after a crash, at the next run) are cut
    off again, so ``/frames`` holds exactly the committed measurements, in order."""

    def __init__(self, path: Path, camera, catalog, committed_frames: int) -> None:
        """``camera``: the model for a frame that does not carry its own
        (``LiveSample.camera_model``)."""
        self.path = path
        self._camera, self._catalog = camera, catalog
        self._writer: CampaignRecordingWriter | None = None
        self._setpoint: SetPointView | None = None
        if path.exists():
            self._writer = CampaignRecordingWriter.reopen(path)
            self._writer.truncate(min(committed_frames, self._writer.n))

    @property
    def n(self) -> int:
        return self._writer.n if self._writer is not None else 0

    def begin_setpoint(self, setpoint: SetPointView) -> None:
        """The set-point the frames appended from now on are measured at."""
        self._setpoint = setpoint

    def check_camera(self, model, set_by_campaign: bool = False) -> None:
        """``RawRecordingError`` when frames taken with ``model`` (the camera's, the
        set-point's settings applied, before it moves) cannot go into the file: it holds
        frames taken at another modulation frequency. ``set_by_campaign``: the campaign's
        own settings chose that frequency (the advice then cannot be to change it back)."""
        held = self._held_hz()
        now = model.modulation_frequency_hz
        if held is None or now == held:
            return
        advice = (
            f"measure at {now / 1e6:g} MHz in a new campaign (this one's file was written "
            f"at {held / 1e6:g} MHz)"
            if set_by_campaign
            else f"set the camera to {held / 1e6:g} MHz and resume"
        )
        raise RawRecordingError(
            f"the camera's modulation frequency is {now / 1e6:g} MHz, but this campaign's "
            f"raw recording holds frames taken at {held / 1e6:g} MHz (one camera model per "
            f"recording): {advice}"
        )

    def _held_hz(self) -> float | None:
        """The modulation frequency of the frames the file holds; None when it holds
        none (a file rolled back to its start is written again with the next frame's
        model)."""
        if self._writer is None or self._writer.n == 0:
            return None
        return self._writer.camera.modulation_frequency_hz

    def append(self, sample: LiveSample) -> int:
        """Write the sample's frame (``/truth`` from its exact pose, ``/reference`` from
        its lab reference, each when the first frame has it) with its wall clock,
        encoders and set-point (``campaign_recording``); returns its index. The file's
        ``/camera`` is the model its first frame was taken with (the set-point's settings
        applied); ``RawRecordingError`` for a frame taken at another modulation frequency
        (``check_camera``)."""
        f = sample.frame
        exact, lab = f.T_camera_target_exact, f.T_camera_target_lab
        model = sample.camera_model or self._camera
        self.check_camera(model)
        if self._writer is not None and self._writer.n == 0:
            self._writer.close()  # nothing in it yet: made again with this frame's model
            self._writer = None
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = CampaignRecordingWriter(
                self.path,
                model,
                self._catalog,
                axes={a: c.rsplit("_", 1)[1] for a, c in AXIS_COLUMNS.items()},
                with_truth=exact is not None,
                with_reference=lab is not None,
            )
        w = self._writer
        index = w.n
        w.append(
            f.gray,
            f.distance_mm,
            float(f.time_s),
            exact.R if exact is not None else None,
            exact.t_mm if exact is not None else None,
            lab_R_camera_target=lab.R if lab is not None else None,
            lab_t_camera_target_mm=lab.t_mm if lab is not None else None,
        )
        sp = self._setpoint
        w.append_motion(
            round(sample.captured_unix_s * 1e9),
            f.meta.get("encoders") or {},
            sp.axes if sp is not None else {},
            sp.index if sp is not None else -1,
        )
        return index

    def rollback(self, n: int) -> None:
        if self._writer is not None:
            self._writer.truncate(n)
            self._writer.flush()

    def flush(self) -> None:
        if self._writer is not None:
            self._writer.flush()

    def close(self) -> None:
        if self._writer is not None:
            self._writer.close()
