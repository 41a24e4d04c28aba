"""Recordings on demand: the live stream written to an HDF5 recording while a person
wants it (``POST /api/recordings``, ``tofpose record``, the dashboard's Record panel).

Each recording subscribes to the live hub, as a campaign's runner does, and writes every
frame the hub delivers to one file in the project's recording format (docs/architecture.md
§7, ``tofpose.io.recording.RecordingWriter``: ``/frames``, ``/truth`` and ``/reference`` when
the source knows them, so ``open_recording``, ``tofpose estimate`` and the MCAP export
read it as they read any recording). Besides those, each frame gets what the live sample
carries, in optional groups that other readers skip:

::

    /frames/index                  int64 (N,)   the driver's frame number
    /frames/wall_time_ns           int64 (N,)   UTC ns when the frame came from the driver
    /frames/capture_ns             int64 (N,)   host monotonic ns: the frame's capture,
    /frames/arrival_ns             int64 (N,)   its arrival and when its pose was ready
    /frames/pose_ready_ns          int64 (N,)   (``backend.services.live.latency``; 0:
                                                none), anchored to UTC by /frames' attrs
                                                monotonic_anchor_ns, wall_anchor_ns
    /pose/ok                       bool (N,)
    /pose/reason                   str (N,)     why not ok ("" when ok)
    /pose/R_camera_target          float64 (N, 3, 3)   NaN when not ok
    /pose/t_camera_target_mm       float64 (N, 3)      NaN when not ok
    /pose/covariance               float64 (N, 6, 6)   (rotation vector rad, translation
                                                       mm); NaN when none
    /pose/residual_mm              float64 (N,)
    /pose/n_matched                int32 (N,)
    /relative_state/valid          bool (N,)    False before the filter's first pose
    /relative_state/status         str (N,)
    /relative_state/R_camera_target, t_camera_target_mm, angular_rate_deg_s,
        angular_rate_target_deg_s, velocity_mm_s   (N, 3, 3) / (N, 3), NaN when not valid
    /relative_state/covariance     float64 (N, 12, 12)
    /motion   attrs: axes (names), units (deg / mm)         only with a motion system
    /motion/positions              float64 (N, A)  the encoders at the frame (the frame's
                                   own reading when the driver gives one, else the last
                                   status read)
    /motion/targets                float64 (N, A)  the set-points of the last status read
    /motion/busy                   bool (N,)
    /motion/status_wall_time_ns    int64 (N,)   UTC ns of that status read (0: none yet)

The motion status is read at most every ``MOTION_POLL_S`` (``MotionService.status``), on
the recording's own thread. A recording stops on request, after its duration, when the
data directory's file system has less than ``min_free_mb`` free (checked before every
frame; a recording is refused from the start below it), on a write error, or when the
server shuts down: the file is then closed and re-opened to count its frames, and the
recording's entry says why it stopped. At most ``MAX_ACTIVE`` record at once.

The metadata (id, name, UTC start and stop, frames, size, state, why it stopped) lives
in ``<directory>/index.json``, beside the files, rewritten atomically at every start,
stop and deletion: the recordings are files, so their list is one too (it moves and is
backed up with them, needs no migration, and the recording thread touches no database).
A recording found ``recording`` at start (the server died) is marked stopped,
``interrupted``, with the frames its file holds.
"""

from __future__ import annotations

import json
import logging
import math
import os
import shutil
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import asdict, dataclass, replace
from datetime import UTC, datetime
from enum import StrEnum
from pathlib import Path

import h5py
import numpy as np

from backend.services.live.acquisition import LiveSample
from backend.services.live.hub import LiveHub, Subscription
from backend.services.live.latency import ClockAnchor
from backend.services.motion import MotionService
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.io.interop import MCAP_SUFFIXES
from tofpose.io.recording import (
    STAMP_ANCHOR_ATTRS,
    STAMP_DATASETS,
    RecordingError,
    RecordingWriter,
    open_recording,
)

log = logging.getLogger(__name__)

MAX_ACTIVE = 2
"""Recordings at once: a long one running in the background and a short one for a
problem; each writes the whole stream (~350 kB a frame of 320 x 240 after gzip: ~3.5 MB/s,
~12 GB an hour at 10 Hz), so more only fill the disk faster with the same frames."""
SUBSCRIPTION_FRAMES = 64
"""Frames a recording's hub subscription buffers (~30 MB of images) before the oldest
is dropped (counted in ``dropped_frames``): a few seconds of slow disk."""
MOTION_POLL_S = 0.2
"""At most this often the recording thread reads the motion status (targets, busy)."""
FLUSH_S = 1.0
"""The file is flushed (and its size read) at least this often: a crash loses at most
the frames of the last second."""
MAX_DURATION_S = 7 * 24 * 3600.0
WAIT_S = 0.1  # the recording thread looks at its stop flag and deadline this often
MB = 1_000_000
INDEX = "index.json"


class RecordingState(StrEnum):
    RECORDING = "recording"
    STOPPED = "stopped"


class StopReason(StrEnum):
    """Why a recording stopped."""

    REQUESTED = "requested"  # a person (API, CLI, dashboard)
    DURATION = "duration"  # its duration_s was reached
    DISK_FULL = "disk_full"  # free space fell below the floor (or the disk was full)
    ERROR = "error"  # a write failed for another reason
    SHUTDOWN = "shutdown"  # the server stopped
    CAMERA_CHANGED = "camera_changed"  # the camera's modulation frequency changed
    INTERRUPTED = "interrupted"  # the server died while it recorded (found at start)


class RecordingNotFoundError(LookupError):
    """No recording with this id."""


class RecordingConflictError(RuntimeError):
    """The request does not fit the recording's state, or too many record already."""


class InsufficientSpaceError(RuntimeError):
    """The data directory's file system has less free space than the floor."""


@dataclass(frozen=True)
class RecordingInfo:
    """A recording's metadata (one entry of the index).

    started_utc, stopped_utc : UTC; duration_s : the duration asked for (None: until
    stopped); frames : written so far; size_bytes : the file's size; dropped_frames : frames
    the hub dropped because the disk could not keep up (not in the file); stop_detail :
    a sentence saying why it stopped ("" while it records); file : the HDF5 file's name
    in the recordings directory.
    """

    id: int
    name: str
    state: RecordingState
    started_utc: datetime
    file: str
    duration_s: float | None = None
    stopped_utc: datetime | None = None
    frames: int = 0
    size_bytes: int = 0
    dropped_frames: int = 0
    stop_reason: StopReason | None = None
    stop_detail: str = ""

    @property
    def elapsed_s(self) -> float:
        end = self.stopped_utc or datetime.now(UTC)
        return max(0.0, (end - self.started_utc).total_seconds())

    def to_json(self) -> dict:
        doc = asdict(self)
        doc["started_utc"] = self.started_utc.isoformat()
        doc["stopped_utc"] = self.stopped_utc.isoformat() if self.stopped_utc else None
        return doc

    @classmethod
    def from_json(cls, doc: dict) -> RecordingInfo:
        stopped = doc.get("stopped_utc")
        reason = doc.get("stop_reason")
        return cls(
            **{
                **doc,
                "state": RecordingState(doc["state"]),
                "started_utc": datetime.fromisoformat(doc["started_utc"]),
                "stopped_utc": datetime.fromisoformat(stopped) if stopped else None,
                "stop_reason": StopReason(reason) if reason else None,
            }
        )


@dataclass(frozen=True)
class MotionReading:
    """The last motion status the recording read: by axis, deg / mm; when (UTC ns)."""

    positions: dict[str, float]
    targets: dict[str, float]
    busy: bool
    wall_time_ns: int


def free_mb(directory: Path) -> float:
    """Free space (MB, 10^6 bytes) of the file system holding ``directory``."""
    return shutil.disk_usage(directory).free / MB


def _ns(unix_s: float) -> int:
    return int(round(unix_s * 1e9))


_NAN3 = np.full(3, np.nan)
_NAN33 = np.full((3, 3), np.nan)


def _or_nan(value, shape: tuple[int, ...]) -> np.ndarray:
    return np.full(shape, np.nan) if value is None else np.asarray(value, float).reshape(shape)


def frame_row(
    sample: LiveSample, axes: tuple[str, ...], motion: MotionReading | None
) -> dict[str, object]:
    """The optional datasets' values for one live sample (module docstring), by path."""
    res, st = sample.result, sample.state
    stamps = sample.stamps
    capture, arrival, pose_ready = (
        (stamps.capture_ns, stamps.arrival_ns, stamps.pose_ready_ns) if stamps else (0, 0, 0)
    )
    row: dict[str, object] = {
        "frames/index": int(sample.frame.index),
        "frames/wall_time_ns": _ns(sample.captured_unix_s),
        STAMP_DATASETS[0]: capture,
        STAMP_DATASETS[1]: arrival,
        STAMP_DATASETS[2]: pose_ready,
        "pose/ok": bool(res.ok),
        "pose/reason": res.reason or "",
        "pose/R_camera_target": _or_nan(res.R if res.ok else None, (3, 3)),
        "pose/t_camera_target_mm": _or_nan(res.t_mm if res.ok else None, (3,)),
        "pose/covariance": _or_nan(res.covariance, (6, 6)),
        "pose/residual_mm": float(res.residual_mm),
        "pose/n_matched": res.n_matched,
        "relative_state/valid": st is not None,
        "relative_state/status": st.status if st is not None else "",
    }
    for name, attr, shape in (
        ("R_camera_target", "R", (3, 3)),
        ("t_camera_target_mm", "t_mm", (3,)),
        ("angular_rate_deg_s", "angular_rate_deg_s", (3,)),
        ("angular_rate_target_deg_s", "angular_rate_target_deg_s", (3,)),
        ("velocity_mm_s", "velocity_mm_s", (3,)),
        ("covariance", "covariance", (12, 12)),
    ):
        row[f"relative_state/{name}"] = _or_nan(getattr(st, attr, None), shape)
    if axes:
        encoders = sample.frame.meta.get("encoders") or (motion.positions if motion else {})
        targets = motion.targets if motion else {}
        row["motion/positions"] = np.array([encoders.get(a, np.nan) for a in axes], float)
        row["motion/targets"] = np.array([targets.get(a, np.nan) for a in axes], float)
        row["motion/busy"] = bool(motion.busy) if motion else False
        row["motion/status_wall_time_ns"] = motion.wall_time_ns if motion else 0
    return row


class LiveRecordingWriter(RecordingWriter):
    """A ``RecordingWriter`` that also keeps, per frame, the live sample's optional
    datasets (``frame_row``): one file in the project's format, with more in it."""

    def __init__(
        self,
        path: Path,
        camera: CameraModel,
        catalog: Catalog | None,
        *,
        with_truth: bool,
        with_reference: bool,
        axes: dict[str, str],
        attrs: dict[str, str | int],
    ) -> None:
        super().__init__(
            path, camera, catalog, with_truth=with_truth, with_reference=with_reference
        )
        f = self._f
        for key, value in attrs.items():
            f.attrs[key] = value
        text = h5py.string_dtype()
        columns: list[tuple[str, tuple[int, ...], object]] = [
            ("frames/index", (), np.int64),
            ("frames/wall_time_ns", (), np.int64),
            *((name, (), np.int64) for name in STAMP_DATASETS),
            ("pose/ok", (), np.bool_),
            ("pose/reason", (), text),
            ("pose/R_camera_target", (3, 3), np.float64),
            ("pose/t_camera_target_mm", (3,), np.float64),
            ("pose/covariance", (6, 6), np.float64),
            ("pose/residual_mm", (), np.float64),
            ("pose/n_matched", (), np.int32),
            ("relative_state/valid", (), np.bool_),
            ("relative_state/status", (), text),
            ("relative_state/R_camera_target", (3, 3), np.float64),
            ("relative_state/t_camera_target_mm", (3,), np.float64),
            ("relative_state/angular_rate_deg_s", (3,), np.float64),
            ("relative_state/angular_rate_target_deg_s", (3,), np.float64),
            ("relative_state/velocity_mm_s", (3,), np.float64),
            ("relative_state/covariance", (12, 12), np.float64),
        ]
        self.axes = tuple(axes)
        if axes:
            n_axes = (len(axes),)
            columns += [
                ("motion/positions", n_axes, np.float64),
                ("motion/targets", n_axes, np.float64),
                ("motion/busy", (), np.bool_),
                ("motion/status_wall_time_ns", (), np.int64),
            ]
        self._columns: dict[str, h5py.Dataset] = {}
        for name, shape, dtype in columns:
            rows = max(1, 16384 // max(1, math.prod(shape)))  # chunks of ~128 kB or less
            self._columns[name] = f.create_dataset(
                name, (0, *shape), dtype, maxshape=(None, *shape), chunks=(min(rows, 256), *shape)
            )
        anchor = ClockAnchor.now()  # the stamps' monotonic clock against UTC
        for key, value in zip(
            STAMP_ANCHOR_ATTRS, (anchor.monotonic_ns, anchor.wall_ns), strict=True
        ):
            f["frames"].attrs[key] = value
        if axes:
            f["motion"].attrs["axes"] = list(axes)
            f["motion"].attrs["units"] = list(axes.values())

    def append_sample(self, sample: LiveSample, motion: MotionReading | None) -> None:
        """Write one live sample: its frame and references (``/truth``, ``/reference``;
        NaN for a frame without the reference this file stores) and ``frame_row``. A
        write that fails part-way is cut off again, so every dataset keeps ``n`` rows."""
        row = frame_row(sample, self.axes, motion)
        f, n = sample.frame, self.n
        exact, lab = f.T_camera_target_exact, f.T_camera_target_lab
        try:
            self.append(
                f.gray,
                f.distance_mm,
                float(f.time_s),
                exact.R if exact is not None else _NAN33,
                exact.t_mm if exact is not None else _NAN3,
                lab_R_camera_target=lab.R if lab is not None else _NAN33,
                lab_t_camera_target_mm=lab.t_mm if lab is not None else _NAN3,
            )
            for name, ds in self._columns.items():
                ds.resize(n + 1, axis=0)
                ds[n] = row[name]
        except BaseException:
            self.truncate(n)
            raise

    def truncate(self, n: int) -> None:
        """Cut every dataset, the optional ones too, to ``n`` frames (also the rows a
        frame that failed part-way left beyond ``n``)."""
        super().truncate(n)
        for ds in self._columns.values():
            if ds.shape[0] > n:
                ds.resize(n, axis=0)


class _Recorder:
    """One recording's thread: hub subscription -> ``LiveRecordingWriter``."""

    def __init__(self, service: RecordingService, info: RecordingInfo, sub: Subscription):
        self.service = service
        self.info = info
        self.path = service.directory / info.file
        self.sub = sub
        self.frames = 0
        self.size_bytes = 0
        self._stop = threading.Event()
        self._stop_reason = StopReason.REQUESTED
        self._writer: LiveRecordingWriter | None = None
        self._motion: MotionReading | None = None
        self._motion_read_at = -math.inf
        self._flushed_at = -math.inf  # the first frame is flushed at once (its size shown)
        self._deadline_unix_s = (
            info.started_utc.timestamp() + info.duration_s
            if info.duration_s is not None
            else math.inf
        )
        self.thread = threading.Thread(target=self._run, name=f"recording-{info.id}", daemon=True)

    def request_stop(self, reason: StopReason) -> None:
        self._stop_reason = reason
        self._stop.set()

    # -- the thread ---------------------------------------------------------------------
    def _run(self) -> None:
        reason, detail = StopReason.ERROR, ""
        try:
            reason, detail = self._record()
        except Exception as exc:  # noqa: BLE001 - the entry says why; the server goes on
            log.exception("recording %d failed", self.info.id)
            reason, detail = StopReason.ERROR, f"recording failed: {exc}"
        finally:
            self.service.hub.unsubscribe(self.sub)
            detail = self._close(detail)
            self.service._finished(self, reason, detail)

    def _record(self) -> tuple[StopReason, str]:
        """Write frames until a stop; returns why it stopped and a sentence saying so."""
        while not self._stop.is_set():
            sample = self.sub.get(WAIT_S)
            if sample is None:
                if time.time() >= self._deadline_unix_s:
                    return StopReason.DURATION, self._duration_detail()
                continue
            if sample.captured_unix_s > self._deadline_unix_s:  # a frame after the end
                return StopReason.DURATION, self._duration_detail()
            if (why := self._write(sample)) is not None:
                return why
        # stopped by a person or the shutdown: what the hub delivered until now goes in too
        self.service.hub.unsubscribe(self.sub)
        while (sample := self.sub.get(0)) is not None:
            if (why := self._write(sample)) is not None:
                return why
        reason = self._stop_reason
        if reason is StopReason.SHUTDOWN:
            return reason, "the server stopped"
        return reason, "stopped on request"

    def _duration_detail(self) -> str:
        return f"its duration of {self.info.duration_s:g} s was reached"

    def _write(self, sample: LiveSample) -> tuple[StopReason, str] | None:
        """Write one frame; why the recording must stop (disk, write error), or None."""
        floor = self.service.min_free_mb
        free = free_mb(self.service.directory)
        if free < floor:
            return StopReason.DISK_FULL, (
                f"stopped: {free:.0f} MB free on the data directory's disk, below the floor "
                f"of {floor:g} MB (TOFPOSE_RECORDING_MIN_FREE_MB)"
            )
        if self._writer is not None and (why := self._camera_change(sample)) is not None:
            return StopReason.CAMERA_CHANGED, why
        try:
            if self._writer is None:
                self._writer = self.service._open_writer(self.info, self.path, sample)
            self._writer.append_sample(sample, self._motion_now())
        except OSError as exc:
            full = getattr(exc, "errno", None) == 28 or "No space" in str(exc)
            kind = StopReason.DISK_FULL if full else StopReason.ERROR
            return kind, f"stopped: writing frame {self.frames} failed ({exc})"
        self.frames = self._writer.n
        now = time.monotonic()
        if now - self._flushed_at >= FLUSH_S:
            self._writer.flush()
            self._flushed_at = now
            self.size_bytes = _size(self.path)
        return None

    def _camera_change(self, sample: LiveSample) -> str | None:
        """Why ``sample`` cannot go into this file: it was taken at another modulation
        frequency than the file's ``/camera`` says (every frame of a recording is read
        with its one camera model: where the distances wrap, their noise); else None."""
        assert self._writer is not None
        now = sample.camera_model
        was_hz = self._writer.camera.modulation_frequency_hz
        if now is None or now.modulation_frequency_hz == was_hz:
            return None
        return (
            f"stopped after frame {self.frames}: the camera's modulation frequency changed "
            f"from {was_hz / 1e6:g} to {now.modulation_frequency_hz / 1e6:g} MHz, and a "
            "recording holds one camera model (/camera), with which every frame is read "
            "(where its distances wrap, their noise): record the new frequency in a new "
            "recording"
        )

    def _motion_now(self) -> MotionReading | None:
        """The last motion status, read again when it is older than ``MOTION_POLL_S``
        (a failing read keeps the older one, whose time says how old it is)."""
        motion = self.service.motion
        if motion is None or not motion.present:
            return None
        now = time.monotonic()
        if now - self._motion_read_at >= MOTION_POLL_S:
            self._motion_read_at = now
            try:
                st = motion.status()
            except Exception as exc:  # noqa: BLE001 - the motion service's health says it
                log.debug("recording %d: no motion status (%s)", self.info.id, exc)
            else:
                self._motion = MotionReading(
                    dict(st.positions), dict(st.targets), bool(st.busy), _ns(time.time())
                )
        return self._motion

    def _close(self, detail: str) -> str:
        """Close the file (made empty if no frame came) and count what it holds; returns
        ``detail``, plus why the file cannot be read when it cannot."""
        try:
            if self._writer is None:
                self._writer = self.service._open_writer(self.info, self.path, None)
            self._writer.close()
        except Exception as exc:  # noqa: BLE001 - said in the entry
            log.exception("recording %d: closing %s failed", self.info.id, self.path)
            detail = f"{detail}; closing the file failed ({exc})"
        try:
            with open_recording(self.path) as rec:
                self.frames = rec.n_frames
        except RecordingError as exc:
            detail = f"{detail}; the file cannot be read ({exc})"
        self.size_bytes = _size(self.path)
        return detail


def _export_files(h5: Path) -> list[Path]:
    """Every file an MCAP export (``campaigns.mcap_files``) may leave beside the recording
    ``h5``: each profile's MCAP (``MCAP_SUFFIXES``) and its note."""
    return [h5.with_suffix(s + extra) for s in MCAP_SUFFIXES.values() for extra in ("", ".json")]


def _size(path: Path) -> int:
    try:
        return path.stat().st_size
    except OSError:
        return 0


class RecordingService:
    """The recordings of one data directory (``AppState.recordings``). Thread-safe.

    camera : the live camera's model; catalog : the live pipeline's catalog now (the
    file keeps the one of its first frame); motion : the motion service, or None.
    min_free_mb : below this much free space a recording is refused, and a running one
    stops.
    """

    def __init__(
        self,
        directory: Path,
        hub: LiveHub,
        camera: CameraModel | Callable[[], CameraModel],
        catalog: Callable[[], Catalog],
        motion: MotionService | None = None,
        *,
        min_free_mb: float = 1000.0,
        max_active: int = MAX_ACTIVE,
    ) -> None:
        self.directory = Path(directory)
        self.hub = hub
        # the camera's model when a recording starts (a callable: the live camera's,
        # which follows its settings, e.g. a new modulation frequency)
        self._camera = camera if callable(camera) else (lambda: camera)
        self.catalog = catalog
        self.motion = motion
        self.min_free_mb = float(min_free_mb)
        self.max_active = max_active
        self._lock = threading.Lock()
        self._infos: dict[int, RecordingInfo] = {}
        self._active: dict[int, _Recorder] = {}
        self._next_id = 1
        self._closed = False
        self.directory.mkdir(parents=True, exist_ok=True)
        self._load()

    # -- the index ----------------------------------------------------------------------

    @property
    def camera(self) -> CameraModel:
        """The camera's model now (what a recording started now writes as ``/camera``)."""
        return self._camera()

    def _load(self) -> None:
        """Read the index; entries left ``recording`` (the server died) become stopped,
        ``interrupted``, with the frames their file holds."""
        # a new id never takes the name of a file already there (whatever the index says)
        ids = [
            int(p.stem.split("-", 1)[1])
            for p in self.directory.glob("recording-*.h5")
            if p.stem.split("-", 1)[1].isdigit()
        ]
        self._next_id = max(ids, default=0) + 1
        path = self.directory / INDEX
        if not path.exists():
            return
        try:
            doc = json.loads(path.read_text())
            entries = [RecordingInfo.from_json(e) for e in doc.get("recordings", [])]
            next_id = int(doc.get("next_id", 1))
        except (OSError, ValueError, TypeError, KeyError) as exc:
            aside = path.with_name(f"{INDEX}.unreadable-{int(time.time())}")
            os.replace(path, aside)
            log.error(
                "the recordings index %s cannot be read (%s): moved to %s; the files "
                "stay, unlisted",
                path,
                exc,
                aside,
            )
            return
        self._next_id = max(self._next_id, next_id)
        for info in entries:
            if info.state is RecordingState.RECORDING:
                info = self._interrupted(info)
            self._infos[info.id] = info
            self._next_id = max(self._next_id, info.id + 1)
        self._save()

    def _interrupted(self, info: RecordingInfo) -> RecordingInfo:
        file = self.directory / info.file
        detail = "the server stopped while it recorded (crash or kill)"
        frames = 0
        try:
            with open_recording(file) as rec:
                frames = rec.n_frames
        except RecordingError as exc:
            detail += f"; the file cannot be read ({exc})"
        stopped = datetime.fromtimestamp(file.stat().st_mtime, UTC) if file.exists() else None
        log.warning(
            "recording %d (%s) was interrupted by a server stop: %d frames kept",
            info.id,
            info.name,
            frames,
        )
        return replace(
            info,
            state=RecordingState.STOPPED,
            stopped_utc=stopped or info.started_utc,
            frames=frames,
            size_bytes=_size(file),
            stop_reason=StopReason.INTERRUPTED,
            stop_detail=detail,
        )

    def _save(self) -> None:
        """Rewrite the index atomically (callers hold the lock, or own the service)."""
        entries = [i.to_json() for i in sorted(self._infos.values(), key=lambda i: i.id)]
        doc = {"version": 1, "next_id": self._next_id, "recordings": entries}
        path = self.directory / INDEX
        tmp = path.with_name(f".{INDEX}.{uuid.uuid4().hex}.tmp")
        try:
            tmp.write_text(json.dumps(doc, indent=1))
            os.replace(tmp, path)
        except OSError:
            tmp.unlink(missing_ok=True)
            log.exception("the recordings index %s could not be written", path)

    # -- commands -----------------------------------------------------------------------
    def start(self, name: str, duration_s: float | None = None) -> RecordingInfo:
        """Start recording the live stream now. ``InsufficientSpaceError`` below the
        free-space floor, ``RecordingConflictError`` when ``max_active`` already record
        (or the service is shut down), ``ValueError`` for a bad duration."""
        if duration_s is not None and not 0 < duration_s <= MAX_DURATION_S:
            raise ValueError(f"duration_s must be in (0, {MAX_DURATION_S:g}] s, got {duration_s}")
        free = free_mb(self.directory)
        if free < self.min_free_mb:
            raise InsufficientSpaceError(
                f"not started: {free:.0f} MB free on the data directory's disk "
                f"({self.directory}), below the floor of {self.min_free_mb:g} MB "
                "(TOFPOSE_RECORDING_MIN_FREE_MB): free some space (delete old recordings)"
            )
        with self._lock:
            if self._closed:
                raise RecordingConflictError("the server is shutting down: no new recording")
            if len(self._active) >= self.max_active:
                running = ", ".join(f"{i} ({r.info.name})" for i, r in self._active.items())
                raise RecordingConflictError(
                    f"{len(self._active)} recordings run already (at most {self.max_active} at "
                    f"once): {running}; stop one first"
                )
            rid = self._next_id
            self._next_id += 1
            info = RecordingInfo(
                rid,
                name,
                RecordingState.RECORDING,
                datetime.now(UTC),
                f"recording-{rid}.h5",
                duration_s,
            )
            sub = self.hub.subscribe(maxsize=SUBSCRIPTION_FRAMES)
            recorder = _Recorder(self, info, sub)
            self._infos[rid] = info
            self._active[rid] = recorder
            self._save()
        recorder.thread.start()
        log.info(
            "recording %d (%s) started%s", rid, name, f" for {duration_s:g} s" if duration_s else ""
        )
        return self.get(rid)

    def stop(
        self, recording_id: int, reason: StopReason = StopReason.REQUESTED, timeout_s: float = 30.0
    ) -> RecordingInfo:
        """Stop a recording (the frames the hub delivered until now are written first) and
        return its final entry; a stopped one is returned as it is."""
        with self._lock:
            recorder = self._active.get(recording_id)
            if recorder is None and recording_id not in self._infos:
                raise RecordingNotFoundError(f"no recording with id {recording_id}")
        if recorder is not None:
            recorder.request_stop(reason)
            recorder.thread.join(timeout_s)
        return self.get(recording_id)

    def stop_all(self, reason: StopReason = StopReason.SHUTDOWN) -> None:
        """Stop every recording and take no new one (the app's shutdown)."""
        with self._lock:
            self._closed = True
            active = list(self._active.values())
        for recorder in active:
            recorder.request_stop(reason)
        for recorder in active:
            recorder.thread.join(30.0)

    def delete(self, recording_id: int) -> None:
        """Delete a stopped recording's entry and files (its HDF5 and MCAP exports);
        ``RecordingConflictError`` while it records."""
        with self._lock:
            info = self._info(recording_id)
            if info.state is RecordingState.RECORDING:
                raise RecordingConflictError(
                    f"recording {recording_id} is recording: stop it first"
                )
            del self._infos[recording_id]
            self._save()
        h5 = self.directory / info.file
        for path in (h5, *_export_files(h5)):
            path.unlink(missing_ok=True)

    # -- reads --------------------------------------------------------------------------
    def _info(self, recording_id: int) -> RecordingInfo:
        info = self._infos.get(recording_id)
        if info is None:
            raise RecordingNotFoundError(f"no recording with id {recording_id}")
        recorder = self._active.get(recording_id)
        if recorder is not None:  # the live counts
            return replace(
                info,
                frames=recorder.frames,
                size_bytes=recorder.size_bytes,
                dropped_frames=recorder.sub.dropped,
            )
        return info

    def running(self) -> list[RecordingInfo]:
        """The recordings that record now, oldest first."""
        with self._lock:
            return [self._info(i) for i in sorted(self._active)]

    def get(self, recording_id: int) -> RecordingInfo:
        with self._lock:
            return self._info(recording_id)

    def list(self) -> list[RecordingInfo]:
        """Every recording, newest first."""
        with self._lock:
            return [self._info(i) for i in sorted(self._infos, reverse=True)]

    def file(self, recording_id: int) -> Path:
        """A stopped recording's HDF5 file; ``RecordingConflictError`` while it records."""
        info = self.get(recording_id)
        if info.state is RecordingState.RECORDING:
            raise RecordingConflictError(
                f"recording {recording_id} is recording: stop it (POST "
                f"/api/recordings/{recording_id}/stop) or wait for its end"
            )
        path = self.directory / info.file
        if not path.exists():
            raise RecordingNotFoundError(f"recording {recording_id}'s file {info.file} is gone")
        return path

    def free_mb(self) -> float:
        return free_mb(self.directory)

    @property
    def used_bytes(self) -> int:
        """What the recordings take on disk (HDF5 files and each profile's MCAP export)."""
        with self._lock:
            files = [self.directory / i.file for i in self._infos.values()]
        return sum(_size(p) + sum(_size(e) for e in _export_files(p)) for p in files)

    # -- for the recorders --------------------------------------------------------------
    def _open_writer(self, info: RecordingInfo, path: Path, first: LiveSample | None):
        """The file, made at the first frame (which says which references it stores)."""
        frame = first.frame if first is not None else None
        axes = (
            {a.name: a.unit for a in self.motion.axes.values()}
            if (self.motion is not None and self.motion.present)
            else {}
        )
        attrs: dict[str, str | int] = {
            "source": "tofpose live recording",
            "recording_id": info.id,
            "name": info.name,
            "started_utc": info.started_utc.isoformat(),
        }
        return LiveRecordingWriter(
            path,
            # the model the first frame was taken with (else the camera's now)
            first.camera_model if first is not None and first.camera_model else self.camera,
            self.catalog(),
            with_truth=frame is not None and frame.T_camera_target_exact is not None,
            with_reference=frame is not None and frame.T_camera_target_lab is not None,
            axes=axes,
            attrs=attrs,
        )

    def _finished(self, recorder: _Recorder, reason: StopReason, detail: str) -> None:
        with self._lock:
            rid = recorder.info.id
            self._active.pop(rid, None)
            if rid not in self._infos:
                return
            self._infos[rid] = replace(
                recorder.info,
                state=RecordingState.STOPPED,
                stopped_utc=datetime.now(UTC),
                frames=recorder.frames,
                size_bytes=recorder.size_bytes,
                dropped_frames=recorder.sub.dropped,
                stop_reason=reason,
                stop_detail=detail,
            )
            self._save()
        log.info(
            "recording %d stopped (%s): %d frames, %.1f MB",
            rid,
            reason.value,
            recorder.frames,
            recorder.size_bytes / MB,
        )


__all__ = [
    "MAX_ACTIVE",
    "InsufficientSpaceError",
    "LiveRecordingWriter",
    "RecordingConflictError",
    "RecordingInfo",
    "RecordingNotFoundError",
    "RecordingService",
    "RecordingState",
    "StopReason",
]
