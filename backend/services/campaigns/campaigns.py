"""Campaigns: a queue of stored set-point sequences, run one at a time, unattended.

States (``campaign_states``; docs/campaigns.md): ``draft`` -> start -> ``queued`` -> (the
scheduler, when the motion system is free and the start time has come) -> ``running`` ->
``done``. A running campaign can be paused (by request, by STOP, by a device fault or a
lost pose lock: ``paused`` with the reason), resumed (back to ``queued``), or cancelled.
A server that stops or dies while a campaign runs leaves it ``interrupted``; resume
continues at the first set-point not done. Nothing moves after a restart without a
person: at start every campaign still ``queued`` is paused ("held at server start"),
and the interrupted ones wait too, until someone resumes them.

``CampaignService`` holds the commands, the scheduler thread and the runner; it composes
the repository (``campaign_repository``: the database and the raw recording), the
set-point collector (``setpoint_collector``: move, settle, collect) and the motion
service (``motion``: a running campaign owns the motion system). Per set-point the runner
collects, then stores the frames and marks the set-point done in one transaction; a
set-point that does not complete stores nothing and is measured again on resume.
"""

from __future__ import annotations

import logging
import threading
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

from sqlalchemy.orm import Session, sessionmaker

from backend.services.campaigns.campaign_camera import CampaignCamera
from backend.services.campaigns.campaign_repository import (
    CampaignNotFoundError,
    CampaignRepository,
    CampaignView,
    RawRecorder,
    RawRecordingError,
    create_campaign,
)
from backend.services.campaigns.campaign_states import (
    CampaignCommand,
    CampaignConflictError,
    CampaignState,
)
from backend.services.campaigns.setpoint_collector import (
    CollectPolicy,
    CollectTiming,
    HubFrames,
    SetPointCollector,
    SetPointHalt,
    SetPointRecord,
)
from backend.services.live.acquisition import AcquisitionService, LiveSample
from backend.services.live.hub import LiveHub
from backend.services.motion import MotionService
from tofpose.sim.bench import LabGeometry

__all__ = [
    "CampaignConflictError",
    "CampaignNotFoundError",
    "CampaignService",
    "Progress",
    "create_campaign",
]

log = logging.getLogger(__name__)


@dataclass
class Progress:
    campaign_id: int
    name: str
    status: CampaignState
    setpoint_index: int
    n_setpoints: int
    n_done: int
    frames_collected: int
    frames_per_point: int
    started_monotonic: float
    done_this_run: int = 0
    camera: dict | None = None  # the camera settings of the set-point in progress

    def as_dict(self) -> dict:
        elapsed = time.monotonic() - self.started_monotonic
        remaining = self.n_setpoints - self.n_done
        eta = (elapsed / self.done_this_run * remaining) if self.done_this_run else None
        return {
            "campaign_id": self.campaign_id,
            "name": self.name,
            "status": self.status,
            "setpoint_index": self.setpoint_index,
            "n_setpoints": self.n_setpoints,
            "n_done": self.n_done,
            "frames_collected": self.frames_collected,
            "frames_per_point": self.frames_per_point,
            "elapsed_s": elapsed,
            "eta_s": eta,
            "camera": self.camera,
        }


def _sets_frequency(*settings: dict | None) -> bool:
    """Whether any of a campaign's camera settings (its own, a set-point's) sets the
    modulation frequency."""
    return any(s and s.get("modulation_frequency_mhz") is not None for s in settings)


class CampaignService:
    """Owns the campaign queue and at most one runner thread. Thread-safe."""

    def __init__(
        self,
        sessions: sessionmaker[Session],
        acquisition: AcquisitionService,
        hub: LiveHub,
        motion: MotionService,
        *,
        poll_s: float = 0.05,
        move_timeout_s: float = 600.0,
        frame_timeout_s: float = 10.0,
        recordings_dir: Path | None = None,
        lab_geometry: LabGeometry | None = None,
    ) -> None:
        self.recordings_dir = recordings_dir
        self.lab_geometry = lab_geometry  # nominal: a dynamic set-point's lab reference
        self.repository = CampaignRepository(sessions)
        self.acquisition = acquisition
        self.hub = hub
        self.motion = motion
        self.timing = CollectTiming(poll_s, move_timeout_s, frame_timeout_s)
        self._lock = threading.Lock()
        self._wake = threading.Event()
        self._shutdown = threading.Event()
        self._scheduler: threading.Thread | None = None
        self._runner: threading.Thread | None = None
        self._running_id: int | None = None
        self._request: tuple[CampaignState, str] | None = None  # (paused | cancelled, why)
        self._progress: Progress | None = None
        self.progress_version = 0
        motion.on_stop(self.stop_pressed)

    # -- lifecycle ------------------------------------------------------------------------
    def recover(self) -> tuple[int, int]:
        """At start: campaigns left ``running`` by a server that died are ``interrupted``,
        and queued ones are paused (nothing moves until a person resumes them). Returns
        (interrupted, held)."""
        return self.repository.recover()

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
        return self.motion.owner

    @property
    def running(self) -> tuple[int, str] | None:
        """(id, name) of the campaign being run now (it sets the camera's settings per
        set-point), or None. Reads without the lock, as ``progress`` does."""
        rid, p = self._running_id, self._progress
        if rid is None:
            return None
        return rid, p.name if p is not None and p.campaign_id == rid else ""

    def progress(self, campaign_id: int | None = None) -> dict | None:
        """The running (or last) campaign's progress. Takes no lock: the live WebSocket
        reads it on the event loop, and the runner holds ``_lock`` across database writes
        and the motion claim; a field read mid-update is at most one frame stale."""
        p = self._progress
        if p is None or (campaign_id is not None and p.campaign_id != campaign_id):
            return None
        return p.as_dict()

    def recording_path(self, campaign_id: int) -> Path:
        if self.recordings_dir is None:
            raise RuntimeError("no directory for campaign recordings is configured")
        return self.recordings_dir / f"campaign-{campaign_id}.h5"

    # -- commands -------------------------------------------------------------------------
    def start_campaign(
        self, campaign_id: int, at: datetime | None = None, *, queue: bool = False
    ) -> None:
        """Queue campaign ``campaign_id`` (now, at ``at``, or behind the running one with
        ``queue``); refused while a STOP is latched (release it first)."""
        if self.motion.present and (latched := self.motion.stop_latched_at) is not None:
            raise CampaignConflictError(
                f"STOP was pressed at {latched:%H:%M:%S} UTC and holds the motion system: "
                "release it (POST /api/motion/release) before starting a campaign"
            )
        owner = self.owner
        if at is None and not queue and owner is not None and owner[0] != campaign_id:
            raise CampaignConflictError(
                f"campaign {owner[0]} ({owner[1]!r}) owns the motion system: start this one "
                'with {"queue": true} to run it next, or at a later time'
            )
        self.repository.apply(campaign_id, CampaignCommand.START, scheduled_at=at)
        self._wake.set()

    def resume(self, campaign_id: int) -> None:
        """A person resumes the campaign: it is queued again, and a latched STOP is
        released (the person has decided the table may move)."""
        with self._lock:  # the scheduler's start (``_begin``) sees both or neither
            self.repository.apply(campaign_id, CampaignCommand.RESUME)
            if self.motion.present:
                self.motion.release_stop()
        self._wake.set()

    def pause(self, campaign_id: int, reason: str = "paused by request") -> None:
        self._halt(campaign_id, CampaignCommand.PAUSE, CampaignState.PAUSED, reason)

    def cancel(self, campaign_id: int) -> None:
        self._halt(
            campaign_id, CampaignCommand.CANCEL, CampaignState.CANCELLED, "cancelled by request"
        )

    def _halt(
        self, campaign_id: int, command: CampaignCommand, status: CampaignState, reason: str
    ) -> None:
        """Ask the runner to leave campaign ``campaign_id`` as ``status``, or, when the
        runner does not hold it, change the stored state. Under the lock the runner takes
        a campaign with (``_begin``), so a command cannot fall between the scheduler's
        pick and the runner's claim and be lost."""
        with self._lock:
            if self._running_id == campaign_id:
                self._request = (status, reason)
                return
            self.repository.apply(campaign_id, command, reason=reason)

    def stop_pressed(self) -> None:
        """STOP: the running campaign (if any) pauses; the turntable is stopped by the
        motion service, whatever the campaign does."""
        with self._lock:
            if self._running_id is not None:
                self._request = (CampaignState.PAUSED, "STOP pressed")

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
                nxt = self.repository.next_due(datetime.now(UTC))
            except Exception:
                log.exception("campaign scheduler could not read the queue")
                continue
            if nxt is not None:
                # the STOP count at the pick: a STOP before the runner claims the motion
                # system keeps the campaign from starting (``_begin``)
                self._runner = threading.Thread(
                    target=self._run,
                    args=(nxt, self.motion.stops),
                    name=f"campaign-{nxt}",
                    daemon=True,
                )
                self._runner.start()

    # -- runner ---------------------------------------------------------------------------
    def _bump(self, **changes) -> None:
        with self._lock:
            if self._progress is not None:
                for k, v in changes.items():
                    setattr(self._progress, k, v)
            self.progress_version += 1

    def _check(self, index: int) -> None:
        """Leave the set-point on shutdown or on a pause or cancel request."""
        if self._shutdown.is_set():
            raise SetPointHalt(
                CampaignState.INTERRUPTED, f"the server shut down during set-point {index}"
            )
        with self._lock:
            req = self._request
        if req is not None:
            raise SetPointHalt(req[0], f"{req[1]} (during set-point {index})")

    def _begin(self, campaign: CampaignView, stops_at_pick: int | None = None) -> bool:
        """The runner holds ``campaign`` and the motion system from now on; False (and
        nothing held) when the campaign is no longer queued (a person paused or cancelled
        it after the scheduler picked it), or when STOP was pressed since the pick
        (``stops_at_pick``: ``MotionService.stops`` then) or still holds the motion system
        (latched): the campaign is paused then."""
        pending = campaign.pending
        with self._lock:
            stopped = stops_at_pick is not None and self.motion.stops != stops_at_pick
            if stopped or (self.motion.present and self.motion.stop_latched):
                self.repository.apply(
                    campaign.id,
                    CampaignCommand.PAUSE,
                    reason="STOP pressed before it started (resume it to release STOP and run it)",
                )
                return False
            # the motion system first: once the campaign reads "running" (to a person, or
            # to a client that polls it), no one else's command reaches the driver
            self.motion.claim(campaign.id, campaign.name)
            try:
                stored = self.repository.set_status(campaign.id, CampaignState.RUNNING)
            except BaseException:  # the database failed: nothing may stay held
                self.motion.release(campaign.id)
                raise
            if not stored:
                self.motion.release(campaign.id)
                log.info(
                    "campaign %d was not run: %s since the scheduler picked it",
                    campaign.id,
                    self.repository.get(campaign.id).status,
                )
                return False
            self._running_id = campaign.id
            self._request = None
            self._progress = Progress(
                campaign.id,
                campaign.name,
                CampaignState.RUNNING,
                pending[0].index if pending else 0,
                len(campaign.setpoints),
                campaign.n_done,
                0,
                campaign.frames_per_point,
                time.monotonic(),
            )
        self._bump()
        return True

    def _end(self, campaign_id: int, final: CampaignState, reason: str) -> None:
        try:
            if not self.repository.set_status(campaign_id, final, reason):
                log.warning(
                    "campaign %d: the runner's %s was not stored (the stored state had changed)",
                    campaign_id,
                    final,
                )
        finally:
            with self._lock:
                self._running_id = None
                self.motion.release(campaign_id)
                if self._progress is not None:
                    self._progress.status = final
            self._bump()
            self._wake.set()

    def _run(self, campaign_id: int, stops_at_pick: int | None = None) -> None:
        campaign = self.repository.get(campaign_id)
        committed_frames = self.repository.committed_frames(campaign_id)
        if not self._begin(campaign, stops_at_pick):
            self._wake.set()  # the scheduler looks for the next one
            return
        sub = None
        final, reason = CampaignState.DONE, ""
        recorder: RawRecorder | None = None
        camera = CampaignCamera(self.acquisition)
        try:
            sub = self.hub.subscribe(maxsize=256)
            self._begin_camera(camera, campaign)
            if campaign.record_raw:
                recorder = RawRecorder(
                    self.recording_path(campaign_id),
                    self.acquisition.camera.model,
                    self.acquisition.catalog,
                    committed_frames,
                )
            self._run_setpoints(campaign, HubFrames(sub, self.acquisition.health), recorder, camera)
        except SetPointHalt as halt:
            final, reason = halt.status, halt.reason
        except Exception as exc:
            log.exception("campaign %d failed", campaign_id)
            final, reason = CampaignState.PAUSED, f"runner error: {exc}"
        finally:
            if sub is not None:
                self.hub.unsubscribe(sub)
            if recorder is not None:
                recorder.close()
            if (why := camera.restore()) is not None:
                reason = f"{reason}; {why}" if reason else why
            self._end(campaign_id, final, reason)

    def _run_setpoints(
        self,
        campaign: CampaignView,
        frames: HubFrames,
        recorder: RawRecorder | None,
        camera: CampaignCamera,
    ) -> None:
        """Collect and store each set-point not done yet, in order, each with its camera
        settings applied first."""
        pending = campaign.pending
        if not self.motion.present and any(sp.axes or sp.profile for sp in pending):
            raise SetPointHalt(CampaignState.FAILED, "no motion system is configured")

        def on_frame(sample: LiveSample, n: int) -> None:
            if recorder is not None:
                try:
                    recorder.append(sample)
                except RawRecordingError as exc:  # the set-point's frames are rolled back
                    raise SetPointHalt(CampaignState.PAUSED, str(exc)) from exc
            self._bump(frames_collected=n)

        collector = SetPointCollector(
            self.motion,
            frames,
            timing=self.timing,
            owner=campaign.id,
            check=self._check,
            on_frame=on_frame,
            lab_geometry=self.lab_geometry,
        )
        for sp in pending:
            self._bump(setpoint_index=sp.index, frames_collected=0, camera=sp.camera)
            start_n = recorder.n if recorder is not None else 0
            if recorder is not None:
                recorder.begin_setpoint(sp)
            self._setpoint_camera(camera, sp.index, sp.camera)
            if recorder is not None:  # before the move: a frequency its file cannot take
                try:
                    recorder.check_camera(
                        self.acquisition.camera.model,
                        set_by_campaign=_sets_frequency(campaign.camera, sp.camera),
                    )
                except RawRecordingError as exc:
                    raise SetPointHalt(CampaignState.PAUSED, str(exc)) from exc
            expected_us = camera.expected_integration_us
            try:
                if sp.profile:
                    record = collector.collect_profile(
                        sp.index, sp.axes, sp.profile, campaign.settle_s, expected_us
                    )
                else:
                    policy = CollectPolicy(
                        campaign.frames_per_point,
                        campaign.settle_s,
                        campaign.lock_timeout_s,
                        expected_us,
                    )
                    record = collector.collect(sp.index, sp.axes, policy)
                if recorder is not None:
                    recorder.flush()  # the frames are on disk before the rows commit
                self._store(sp.id, record, start_n if recorder is not None else None)
            except BaseException:
                if recorder is not None:  # frames on disk only with their rows committed
                    recorder.rollback(start_n)
                raise

    def _store(self, setpoint_id: int, record: SetPointRecord, first_index: int | None) -> None:
        self.repository.store_setpoint(setpoint_id, record.frames, first_index)
        with self._lock:
            if self._progress is not None:
                self._progress.n_done += 1
                self._progress.done_this_run += 1
        self._bump()

    @staticmethod
    def _begin_camera(camera: CampaignCamera, campaign: CampaignView) -> None:
        """Remember the camera's settings (restored when the campaign leaves) and apply
        the campaign-wide ones before the first set-point."""
        try:
            camera.begin(dict(campaign.camera) if campaign.camera else None)
        except Exception as exc:
            raise SetPointHalt(
                CampaignState.PAUSED, f"the camera refused the campaign's settings: {exc}"
            ) from exc

    @staticmethod
    def _setpoint_camera(camera: CampaignCamera, index: int, setting: dict | None) -> None:
        """The set-point's camera settings, applied before it moves (so every frame it
        counts, captured after the settle, was taken with them)."""
        try:
            camera.for_setpoint(setting)
        except Exception as exc:
            raise SetPointHalt(
                CampaignState.PAUSED,
                f"the camera refused the settings of set-point {index} ({setting}): {exc}",
            ) from exc
