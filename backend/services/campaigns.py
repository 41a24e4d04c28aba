"""Campaigns: a queue of stored set-point sequences, run one at a time, unattended.

States (docs/campaigns.md): ``draft`` -> start -> ``queued`` -> (the scheduler, when the
motion system is free and the start time has come) -> ``running`` -> ``done``. A running
campaign can be paused (by request, by STOP, by a device fault or a lost pose lock:
``paused`` with the reason), resumed (back to ``queued``), or cancelled. A server that
stops or dies while a campaign runs leaves it ``interrupted``; resume continues at the
first set-point not done.

The runner, per set-point: move; wait until the motion system reports settled; then
count only frames captured after that moment and at least ``settle_s`` of device time
later, whose encoder read-back (when the driver gives it) is at the set-point; collect
``frames_per_point`` of them; store them and mark the set-point done in one transaction.
A set-point that does not complete stores nothing and is measured again on resume.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
from sqlalchemy import func, select
from sqlalchemy.orm import Session, sessionmaker

from backend.db.models import CampaignRow, MeasurementRow, SetPointRow, utcnow
from backend.drivers.base import MotionDriver, profile_problems, soft_limit_problems
from backend.services.acquisition import AcquisitionService, LiveSample
from backend.services.encoder_trace import EncoderTrace, EncoderTraceError
from backend.services.hub import LiveHub
from backend.services.store import commit_unique
from tofpose.geometry import RigidTransform, facing_euler_deg, facing_euler_sigma_deg
from tofpose.motion_profile import profile_from_spec
from tofpose.recording import RecordingWriter
from tofpose.sim.bench import LabGeometry

log = logging.getLogger(__name__)

AXIS_COLUMNS = {"yaw": "yaw_deg", "pitch": "pitch_deg", "roll": "roll_deg", "rail": "rail_mm"}
# Encoder read-back farther than this from the set-point means the axis is not there.
AT_SETPOINT_TOLERANCE = {"yaw": 0.05, "pitch": 0.05, "roll": 0.05, "rail": 1.0}
# A profile pauses when the motion status has not been read for this long (s, wall time).
STALE_TRACE_S = 1.0
ACTIVE = ("running",)
RESUMABLE = ("paused", "interrupted")
FINISHED = ("done", "failed", "cancelled")


class CampaignNotFoundError(LookupError):
    """No campaign with this id."""


class CampaignConflictError(RuntimeError):
    """The request conflicts with the campaign's state or with another campaign."""


class _Halt(Exception):  # noqa: N818 (control flow, not an error)
    """Raised inside the runner to leave a set-point: pause, cancel or shutdown."""

    def __init__(self, status: str, reason: str) -> None:
        super().__init__(reason)
        self.status = status
        self.reason = reason


@dataclass
class Progress:
    campaign_id: int
    name: str
    status: str
    setpoint_index: int
    n_setpoints: int
    n_done: int
    frames_collected: int
    frames_per_point: int
    started_monotonic: float
    done_this_run: int = 0

    def as_dict(self) -> dict:
        elapsed = time.monotonic() - self.started_monotonic
        remaining = self.n_setpoints - self.n_done
        eta = (elapsed / self.done_this_run * remaining) if self.done_this_run else None
        return {
            "campaign_id": self.campaign_id, "name": self.name, "status": self.status,
            "setpoint_index": self.setpoint_index, "n_setpoints": self.n_setpoints,
            "n_done": self.n_done, "frames_collected": self.frames_collected,
            "frames_per_point": self.frames_per_point, "elapsed_s": elapsed, "eta_s": eta,
        }  # fmt: skip


def measurement_row(setpoint_id: int, sample: LiveSample) -> MeasurementRow:
    """One stored frame: pose (facing Euler), sigmas, exact truth (``truth_*``, from the
    frame's ``T_camera_target_exact``) and the lab's reference (``lab_truth_*``, from
    ``T_camera_target_lab``), encoders, and the relative-state filter's rates and
    velocity with their sigmas."""
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
    )
    if r.ok and r.R is not None:
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
            ("rate_{}_deg_s", st.angular_rate_deg_s), ("vel_{}_mm_s", st.velocity_mm_s),
            ("sigma_rate_{}_deg_s", st.angular_rate_sigma_deg_s),
            ("sigma_vel_{}_mm_s", st.velocity_sigma_mm_s),
        ):  # fmt: skip
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


def _finite(v) -> float | None:
    v = float(v)
    return v if np.isfinite(v) else None


class RawRecorder:
    """A campaign's raw frames in an HDF5 recording (docs/architecture.md §7), kept equal
    to what the database holds: frames are appended as they are measured, the file is
    flushed before the set-point's transaction commits, and frames of a set-point that
    did not complete (pause, cancel, shutdown; after a crash, at the next run) are cut
    off again, so ``/frames`` holds exactly the committed measurements, in order."""

    def __init__(self, path: Path, camera, catalog, committed_frames: int) -> None:
        self.path = path
        self._camera, self._catalog = camera, catalog
        self._writer: RecordingWriter | None = None
        if path.exists():
            self._writer = RecordingWriter.reopen(path)
            self._writer.truncate(min(committed_frames, self._writer.n))

    @property
    def n(self) -> int:
        return self._writer.n if self._writer is not None else 0

    def append(self, sample: LiveSample) -> int:
        """Write the sample's frame (``/truth`` from its exact pose, ``/lab_truth`` from
        its lab reference, each when the first frame has it); returns its index."""
        f = sample.frame
        exact, lab = f.T_camera_target_exact, f.T_camera_target_lab
        if self._writer is None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._writer = RecordingWriter(
                self.path, self._camera, self._catalog,
                with_truth=exact is not None, with_lab_truth=lab is not None,
            )  # fmt: skip
        w = self._writer
        index = w.n
        w.append(
            f.gray, f.distance_mm, float(f.time_s),
            exact.R if exact is not None else None, exact.t_mm if exact is not None else None,
            lab_R_camera_target=lab.R if lab is not None else None,
            lab_t_camera_target_mm=lab.t_mm if lab is not None else None,
        )  # fmt: skip
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


class CampaignService:
    """Owns the campaign queue and at most one runner thread. Thread-safe."""

    def __init__(
        self,
        sessions: sessionmaker[Session],
        acquisition: AcquisitionService,
        hub: LiveHub,
        motion: MotionDriver | None,
        *,
        poll_s: float = 0.05,
        move_timeout_s: float = 600.0,
        frame_timeout_s: float = 10.0,
        recordings_dir: Path | None = None,
        lab_geometry: LabGeometry | None = None,
    ) -> None:
        self.recordings_dir = recordings_dir
        self.lab_geometry = lab_geometry  # nominal: a dynamic set-point's lab reference
        self.sessions = sessions
        self.acquisition = acquisition
        self.hub = hub
        self.motion = motion
        self.poll_s = poll_s
        self.move_timeout_s = move_timeout_s
        self.frame_timeout_s = frame_timeout_s
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._shutdown = threading.Event()
        self._scheduler: threading.Thread | None = None
        self._runner: threading.Thread | None = None
        self._running_id: int | None = None
        self._request: tuple[str, str] | None = None  # ("paused" | "cancelled", reason)
        self._progress: Progress | None = None
        self.progress_version = 0

    # -- lifecycle ------------------------------------------------------------------------
    def recover(self) -> int:
        """At start: campaigns left ``running`` by a server that died are ``interrupted``."""
        with self.sessions() as s, s.begin():
            rows = s.scalars(select(CampaignRow).where(CampaignRow.status.in_(ACTIVE))).all()
            for row in rows:
                row.status = "interrupted"
                row.status_reason = "the server stopped while this campaign was running"
            return len(rows)

    def start(self) -> None:
        self._scheduler = threading.Thread(target=self._schedule, name="campaigns", daemon=True)
        self._scheduler.start()

    def stop(self, timeout_s: float = 5.0) -> None:
        """Shutdown: a running campaign is left ``interrupted`` (resumable)."""
        self._shutdown.set()
        self._wake.set()
        for t in (self._runner, self._scheduler):
            if t is not None:
                t.join(timeout_s)

    # -- what the API reads -------------------------------------------------------------------
    @property
    def owner(self) -> tuple[int, str] | None:
        """(id, name) of the campaign that owns the motion system now, or None."""
        with self._lock:
            p = self._progress
            return (p.campaign_id, p.name) if p is not None and self._running_id else None

    def progress(self, campaign_id: int | None = None) -> dict | None:
        with self._lock:
            p = self._progress
            if p is None or (campaign_id is not None and p.campaign_id != campaign_id):
                return None
            return p.as_dict()

    # -- commands -------------------------------------------------------------------------
    def _get(self, s: Session, campaign_id: int) -> CampaignRow:
        row = s.get(CampaignRow, campaign_id)
        if row is None:
            raise CampaignNotFoundError(f"no campaign with id {campaign_id}")
        return row

    def start_campaign(
        self, campaign_id: int, at: datetime | None = None, *, queue: bool = False
    ) -> None:
        owner = self.owner
        if at is None and not queue and owner is not None and owner[0] != campaign_id:
            raise CampaignConflictError(
                f"campaign {owner[0]} ({owner[1]!r}) owns the motion system: start this one "
                'with {"queue": true} to run it next, or at a later time'
            )
        with self.sessions() as s, s.begin():
            row = self._get(s, campaign_id)
            if row.status not in ("draft", "queued"):
                raise CampaignConflictError(
                    f"campaign {campaign_id} is {row.status}: only a draft or queued campaign "
                    "can be started (resume a paused or interrupted one)"
                )
            row.status = "queued"
            row.status_reason = ""
            row.scheduled_at = at
        self._wake.set()

    def resume(self, campaign_id: int) -> None:
        with self.sessions() as s, s.begin():
            row = self._get(s, campaign_id)
            if row.status not in RESUMABLE:
                raise CampaignConflictError(
                    f"campaign {campaign_id} is {row.status}: only a paused or interrupted "
                    "campaign can be resumed" + ("; it has nothing left to do" if
                                                 row.status == "done" else "")
                )  # fmt: skip
            row.status = "queued"
            row.status_reason = ""
            row.scheduled_at = None
        self._wake.set()

    def pause(self, campaign_id: int, reason: str = "paused by request") -> None:
        with self._lock:
            if self._running_id == campaign_id:
                self._request = ("paused", reason)
                return
        with self.sessions() as s, s.begin():
            row = self._get(s, campaign_id)
            if row.status != "queued":
                raise CampaignConflictError(
                    f"campaign {campaign_id} is {row.status}: only a running or queued "
                    "campaign can be paused"
                )
            row.status, row.status_reason = "paused", reason

    def cancel(self, campaign_id: int) -> None:
        with self._lock:
            if self._running_id == campaign_id:
                self._request = ("cancelled", "cancelled by request")
                return
        with self.sessions() as s, s.begin():
            row = self._get(s, campaign_id)
            if row.status in FINISHED:
                raise CampaignConflictError(f"campaign {campaign_id} is already {row.status}")
            row.status, row.status_reason = "cancelled", "cancelled by request"
            row.finished_at = utcnow()

    def stop_pressed(self) -> None:
        """STOP: the running campaign (if any) pauses; the turntable is stopped by the
        caller, whatever the campaign does."""
        with self._lock:
            if self._running_id is not None:
                self._request = ("paused", "STOP pressed")

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no runner is active (tests, shutdown)."""
        t = self._runner
        if t is not None:
            t.join(timeout_s)
            return not t.is_alive()
        return True

    # -- scheduler --------------------------------------------------------------------------
    def _schedule(self) -> None:
        while not self._shutdown.is_set():
            self._wake.wait(0.25)
            self._wake.clear()
            if self._shutdown.is_set():
                return
            if self._runner is not None and self._runner.is_alive():
                continue
            try:
                nxt = self._next_due()
            except Exception:
                log.exception("campaign scheduler could not read the queue")
                continue
            if nxt is not None:
                self._runner = threading.Thread(
                    target=self._run, args=(nxt,), name=f"campaign-{nxt}", daemon=True
                )
                self._runner.start()

    def _next_due(self) -> int | None:
        now = datetime.now(UTC)
        with self.sessions() as s:
            rows = s.scalars(
                select(CampaignRow)
                .where(CampaignRow.status == "queued")
                .order_by(
                    CampaignRow.scheduled_at.is_not(None), CampaignRow.scheduled_at, CampaignRow.id
                )  # fmt: skip
            ).all()
            for row in rows:
                at = row.scheduled_at
                if at is not None and at.tzinfo is None:
                    at = at.replace(tzinfo=UTC)  # SQLite returns naive datetimes
                if at is None or at <= now:
                    return row.id
        return None

    # -- runner ---------------------------------------------------------------------------
    def _set_status(self, campaign_id: int, status: str, reason: str = "") -> None:
        with self.sessions() as s, s.begin():
            row = s.get(CampaignRow, campaign_id)
            row.status, row.status_reason = status, reason
            if status == "running" and row.started_at is None:
                row.started_at = utcnow()
            if status in FINISHED:
                row.finished_at = utcnow()

    def _bump(self, **changes) -> None:
        with self._lock:
            if self._progress is not None:
                for k, v in changes.items():
                    setattr(self._progress, k, v)
            self.progress_version += 1

    def _run(self, campaign_id: int) -> None:
        with self.sessions() as s:
            row = s.get(CampaignRow, campaign_id)
            pending = [sp for sp in row.setpoints if sp.status != "done"]
            n_total, n_done = len(row.setpoints), len(row.setpoints) - len(pending)
            plan = [(sp.id, sp.index, setpoint_axes(sp), sp.profile) for sp in pending]
            name, frames, settle_s = row.name, row.frames_per_point, row.settle_s
            lock_timeout_s = row.lock_timeout_s
            record_raw = row.record_raw
            camera_settings = dict(row.camera_settings or {})
            committed_frames = s.scalar(
                select(func.count())
                .select_from(MeasurementRow)
                .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
                .where(SetPointRow.campaign_id == campaign_id)
            )
        with self._lock:
            self._running_id = campaign_id
            self._request = None
            self._progress = Progress(campaign_id, name, "running", plan[0][1] if plan else 0,
                                      n_total, n_done, 0, frames, time.monotonic())  # fmt: skip
        self._set_status(campaign_id, "running")
        self._bump()
        sub = self.hub.subscribe(maxsize=256)
        final, reason = "done", ""
        recorder: RawRecorder | None = None
        try:
            if camera_settings:
                self._apply_camera(camera_settings)
            if record_raw:
                recorder = RawRecorder(
                    self.recording_path(campaign_id), self.acquisition.camera.model,
                    self.acquisition.catalog, committed_frames,
                )  # fmt: skip
            if self.motion is None and any(axes or prof for _, _, axes, prof in plan):
                raise _Halt("failed", "no motion system is configured")
            for sp_id, index, axes, profile in plan:
                self._bump(setpoint_index=index, frames_collected=0)
                start_n = recorder.n if recorder is not None else 0
                try:
                    if profile:
                        samples = self._measure_profile(
                            sub, index, axes, profile, settle_s, recorder
                        )
                    else:
                        samples = [
                            (x, None) for x in self._measure(
                                sub, index, axes, frames, settle_s, lock_timeout_s, recorder
                            )
                        ]  # fmt: skip
                    if recorder is not None:
                        recorder.flush()  # the frames are on disk before the rows commit
                except BaseException:
                    if recorder is not None:
                        recorder.rollback(start_n)
                    raise
                with self.sessions() as s, s.begin():
                    for k, (x, in_motion) in enumerate(samples):
                        m = measurement_row(sp_id, x)
                        m.in_motion = in_motion
                        m.recording_index = start_n + k if recorder is not None else None
                        s.add(m)
                    sp = s.get(SetPointRow, sp_id)
                    sp.status, sp.completed_at = "done", utcnow()
                with self._lock:
                    self._progress.n_done += 1
                    self._progress.done_this_run += 1
                self._bump()
        except _Halt as halt:
            final, reason = halt.status, halt.reason
        except Exception as exc:
            log.exception("campaign %d failed", campaign_id)
            final, reason = "paused", f"runner error: {exc}"
        finally:
            self.hub.unsubscribe(sub)
            if recorder is not None:
                recorder.close()
            try:
                self._set_status(campaign_id, final, reason)
            finally:
                with self._lock:
                    self._running_id = None
                    if self._progress is not None:
                        self._progress.status = final
                self._bump()
                self._wake.set()

    def _apply_camera(self, wanted: dict) -> None:
        """The campaign's camera settings, applied on the acquisition thread before the
        first set-point (the camera keeps them afterwards, as with PUT /api/camera)."""
        cam = self.acquisition.camera
        target = replace(cam.get_settings(), **wanted)
        try:
            self.acquisition.submit(lambda: cam.apply_settings(target)).result(10.0)
        except Exception as exc:
            raise _Halt("paused", f"the camera refused the campaign's settings: {exc}") from exc

    def _check(self, index: int) -> None:
        if self._shutdown.is_set():
            raise _Halt("interrupted", f"the server shut down during set-point {index}")
        with self._lock:
            req = self._request
        if req is not None:
            raise _Halt(req[0], f"{req[1]} (during set-point {index})")

    def recording_path(self, campaign_id: int) -> Path:
        if self.recordings_dir is None:
            raise RuntimeError("no directory for campaign recordings is configured")
        return self.recordings_dir / f"campaign-{campaign_id}.h5"

    def _move_and_settle(self, index: int, axes: dict[str, float]) -> None:
        """Move to ``axes`` (if any) and wait until the motion system reports settled."""
        self._check(index)
        if axes:
            try:
                self.motion.move_to(axes)
            except Exception as exc:
                raise _Halt("paused", f"move to set-point {index} failed: {exc}") from exc
            deadline = time.monotonic() + self.move_timeout_s
            while True:
                self._check(index)
                try:
                    st = self.motion.status()
                except Exception as exc:
                    msg = f"motion status failed at set-point {index}: {exc}"
                    raise _Halt("paused", msg) from exc
                if st.stopped:
                    raise _Halt("paused", f"the turntable was stopped at set-point {index}")
                if st.settled and not st.busy:
                    break
                if time.monotonic() > deadline:
                    raise _Halt("paused", f"set-point {index} not settled within "
                                          f"{self.move_timeout_s:g} s")  # fmt: skip
                time.sleep(self.poll_s)

    def _next_sample(self, sub, index: int) -> LiveSample:
        """The next live sample; pauses the campaign after ``frame_timeout_s`` without one."""
        waited_since = time.monotonic()
        while True:
            self._check(index)
            sample = sub.get(self.poll_s)
            if sample is not None:
                return sample
            if time.monotonic() - waited_since > self.frame_timeout_s:
                h = self.acquisition.health
                msg = (
                    f"no frame for {self.frame_timeout_s:g} s at set-point {index} "
                    f"(camera {h.state}: {h.last_error})"
                )
                raise _Halt("paused", msg)

    def _measure(
        self, sub, index: int, axes: dict[str, float], frames: int, settle_s: float,
        lock_timeout_s: float, recorder: RawRecorder | None = None,
    ) -> list[LiveSample]:  # fmt: skip
        """Move to ``axes`` and collect ``frames`` samples taken at rest (see module)."""
        self._move_and_settle(index, axes)
        settled_unix_s = time.time()
        while sub.get(0.0) is not None:  # frames queued before the settle do not count
            pass
        t_ready = None
        last_ok_s = None
        out: list[LiveSample] = []
        while len(out) < frames:
            sample = self._next_sample(sub, index)
            if sample.captured_unix_s < settled_unix_s or not sample.measured:
                continue  # before the settle, or while the pipeline's kernels compile
            t = float(sample.frame.time_s)
            if t_ready is None:
                t_ready = t + settle_s
                last_ok_s = t_ready
            if t < t_ready:
                continue
            enc = sample.frame.meta.get("encoders") or {}
            off = [
                a
                for a, v in axes.items()
                if a in enc and abs(enc[a] - v) > AT_SETPOINT_TOLERANCE.get(a, 0.05)
            ]
            if off:
                raise _Halt("paused", f"the turntable left set-point {index} (axes {off})")
            if sample.result.ok:
                last_ok_s = t
            elif t - last_ok_s > lock_timeout_s:
                raise _Halt("paused", f"pose lock lost for {t - last_ok_s:.1f} s at set-point "
                                      f"{index}: {sample.result.reason}")  # fmt: skip
            if recorder is not None:
                recorder.append(sample)
            out.append(sample)
            self._bump(frames_collected=len(out))
        return out

    def _measure_profile(
        self, sub, index: int, axes: dict[str, float], spec: dict, settle_s: float,
        recorder: RawRecorder | None = None,
    ) -> list[tuple[LiveSample, bool]]:  # fmt: skip
        """A dynamic set-point (docs/campaigns.md, "Dynamic campaigns"): move and settle;
        rest ``rest_s``; run the profile from the axis' encoder position; rest ``rest_s``
        after it has ended. Every measured frame of the three phases is kept, its encoders
        and lab reference interpolated to its capture time (``EncoderTrace``), with
        whether the profile ran at that time. A lost pose does not pause it: frames lost
        in motion are what the report counts."""
        axis, rest_s = spec["axis"], float(spec.get("rest_s", 2.0))
        self._move_and_settle(index, axes)
        trace = EncoderTrace(self.motion)
        try:
            trace.start()
        except EncoderTraceError as exc:
            raise _Halt("failed", str(exc)) from exc
        except Exception as exc:
            raise _Halt("paused", f"motion status failed at set-point {index}: {exc}") from exc
        running = False
        try:
            settled_unix_s = time.time()
            while sub.get(0.0) is not None:  # frames queued before the settle do not count
                pass
            out: list[tuple[LiveSample, bool]] = []
            t_ready = t0 = t_end = deadline = None
            while True:
                sample = self._next_sample(sub, index)
                if sample.captured_unix_s < settled_unix_s or not sample.measured:
                    continue
                t = float(sample.frame.time_s)
                t_ready = t + settle_s if t_ready is None else t_ready
                if t < t_ready:
                    continue
                if t0 is None and t >= t_ready + rest_s:
                    running = True  # from here on, any way out stops the table first
                    t0, t_end = self._start_profile(index, axis, spec)
                    deadline = time.monotonic() + (t_end - t0) + self.move_timeout_s
                out.append((self._referenced(sample, trace), t0 is not None and t0 <= t <= t_end))
                if recorder is not None:
                    recorder.append(out[-1][0])
                self._bump(frames_collected=len(out))
                if t0 is None:
                    continue
                if trace.stale_s() > STALE_TRACE_S:
                    why = trace.error or "no answer"
                    raise _Halt("paused", f"the motion status was not read for "
                                          f"{trace.stale_s():.1f} s during the profile of "
                                          f"set-point {index}: {why}")  # fmt: skip
                st = trace.latest
                if st.stopped:
                    raise _Halt("paused", f"the turntable was stopped at set-point {index}")
                if t >= t_end + rest_s:
                    if st.profile is None and st.settled and not st.busy:
                        running = False
                        return out
                    if time.monotonic() > deadline:
                        raise _Halt("paused", f"the {axis} profile of set-point {index} did not "
                                              f"end within {self.move_timeout_s:g} s of its "
                                              "duration")  # fmt: skip
        except BaseException:
            if running:  # a pause, cancel, shutdown or failure stops the slew it interrupts
                try:
                    self.motion.stop()
                except Exception:
                    log.exception("stopping the profile of set-point %d failed", index)
            raise
        finally:
            trace.stop()

    def _start_profile(self, index: int, axis: str, spec: dict) -> tuple[float, float]:
        """Start the set-point's profile from the axis' encoder position now; returns
        (start, end) on the encoders' clock."""
        motion = self.motion
        why = getattr(motion, "profile_unavailable", "it has no profile mode")
        if not callable(getattr(motion, "run_profile", None)) or why is not None:
            raise _Halt("failed", f"set-point {index}: the {motion.name!r} motion system cannot "
                                  f"run motion profiles ({why})")  # fmt: skip
        try:
            start_deg = motion.status().positions[axis]
            profile = profile_from_spec(spec, motion.axes[axis].max_accel).started_at(start_deg)
        except Exception as exc:
            raise _Halt("paused", f"set-point {index}: cannot prepare the profile: {exc}") from exc
        problems = profile_problems(motion.axes, axis, profile)
        if problems:
            raise _Halt("failed", f"set-point {index}: " + "; ".join(p.message for p in problems))
        try:
            motion.run_profile(axis, profile)
            st = motion.status()
        except Exception as exc:
            raise _Halt("paused", f"set-point {index}: the profile failed: {exc}") from exc
        elapsed = st.profile.elapsed_s if st.profile is not None else 0.0
        t0 = float(st.time_s) - elapsed
        return t0, t0 + profile.duration_s

    def _referenced(self, sample: LiveSample, trace: EncoderTrace) -> LiveSample:
        """The sample with the encoders interpolated to its capture time and the lab
        reference from them (the nominal geometry), when the trace covers that time."""
        enc = trace.at(float(sample.frame.time_s))
        f = sample.frame
        if enc is None:  # no reading around its capture: no reference rather than a late one
            meta = {k: v for k, v in f.meta.items() if k != "encoders"}
            return replace(sample, frame=replace(f, T_camera_target_lab=None, meta=meta), cache={})
        T_lab = f.T_camera_target_lab
        if self.lab_geometry is not None:
            T_lab = self.lab_geometry.T_camera_target(enc, true=False)
        frame = replace(f, T_camera_target_lab=T_lab, meta={**f.meta, "encoders": enc})
        return replace(sample, frame=frame, cache={})


def setpoint_axes(sp: SetPointRow) -> dict[str, float]:
    return {
        a: float(getattr(sp, col))
        for a, col in AXIS_COLUMNS.items()
        if getattr(sp, col) is not None
    }


def plan_problems(
    setpoints: list[dict[str, float]],
    axes: dict | None,
    *,
    frames_per_point: int,
    max_setpoints: int,
    max_frames: int,
) -> list[str]:
    """Why a set-point list cannot run on this motion system (empty when it can): empty
    or too long, too many frames in all, unknown axes or values outside the soft limits
    (each named with its index)."""
    if not setpoints:
        return ["the campaign has no set-points: give a non-empty 'setpoints' or a generator"]
    problems = []
    if len(setpoints) > max_setpoints:
        problems.append(f"{len(setpoints)} set-points is more than the maximum {max_setpoints}")
    if len(setpoints) * frames_per_point > max_frames:
        problems.append(
            f"{len(setpoints)} set-points x {frames_per_point} frames is more than the "
            f"maximum {max_frames} frames per campaign"
        )
    if axes is None:
        if any(setpoints):
            problems.append("no motion system is configured: set-points cannot be reached")
        return problems
    for i, sp in enumerate(setpoints):
        problems += [f"set-point {i}: {p}" for p in soft_limit_problems(axes, sp)]
        if len(problems) > 20:
            problems.append("... (more)")
            break
    return problems


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
) -> CampaignRow:
    """Store a draft campaign with its set-points (and, for a dynamic one, the motion
    profile of each); ``NameTakenError`` if the name exists."""
    row = CampaignRow(
        name=name, status="draft", status_reason="", catalog_name=catalog_name,
        frames_per_point=frames_per_point, settle_s=settle_s, lock_timeout_s=lock_timeout_s,
        requirements=requirements, generator=generator, camera_settings=camera, notes=notes,
        record_raw=record_raw,
    )  # fmt: skip
    for i, sp in enumerate(setpoints):
        row.setpoints.append(
            SetPointRow(
                index=i,
                status="pending",
                profile=profiles[i] if profiles else None,
                **{AXIS_COLUMNS[a]: float(v) for a, v in sp.items()},
            )  # fmt: skip
        )
    s.add(row)
    commit_unique(s, f"a campaign named {name!r}")
    return row
