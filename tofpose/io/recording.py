"""HDF5 recordings (docs/architecture.md §7): one file per recording, frames with optional
truth and reference poses.

::

    /            attrs: format = "tofpose-recording", version = 1
    /camera      attrs: width, height, fx, fy, cx, cy, dist (5), name,
                        full_scale_counts, modulation_frequency_hz,
                        unwrapped_range_mm (only when set), count_scale,
                        distance_kind, depth_unit_mm, depth_invalid_code,
                        depth_max_valid_code (all optional: a recording without
                        them reads as the EPC660's: 4095 counts, 6 MHz, count
                        scale 1, radial distances, mm codes, 0 and > 63999 invalid)
    /catalog     attrs: json                                              optional
    /frames/gray          uint16  (N, H, W)
    /frames/distance_mm   float32 (N, H, W)  mm, NaN = invalid: radial distance,
                                             or z depth where /camera's
                                             distance_kind is "z"
    /frames/time_s        float64 (N,)
    /truth/R_camera_target     float64 (N, 3, 3)                          optional
    /truth/t_camera_target_mm  float64 (N, 3)                             optional
    /reference/R_camera_target     float64 (N, 3, 3)                      optional
    /reference/t_camera_target_mm  float64 (N, 3)                         optional

Recordings of the server's live stream may also carry each frame's stamps on the host's
monotonic clock (int64 ns, ``time.monotonic_ns``), with the anchor that turns them into
UTC in ``/frames``' attributes (``monotonic_anchor_ns``, ``wall_anchor_ns``: one moment
read on both clocks)::

    /frames/capture_ns     int64 (N,)  when the device captured the frame (its clock
                                       mapped to the host's; docs/server.md, "Latency
                                       and dropped frames")
    /frames/arrival_ns     int64 (N,)  when the frame reached the server
    /frames/pose_ready_ns  int64 (N,)  when its pose was ready

A recording without them (every recording written before them, and ``tofpose
simulate``'s) reads as before, with ``Recording.stamps`` None.

``/truth`` is the pose that produced each frame, known only where a simulator rendered it;
``/reference`` is the lab's estimate of it (encoders + nominal mount and placement), the
only reference a real lab has. A simulated recording carries both; a campaign on real
hardware only ``/reference`` (docs/interop.md, "Names: truth and reference").

Recordings written before the rename hold the reference as ``/lab_truth``: the reader
takes it as ``/reference`` (``LEGACY_GROUPS``) and ``RecordingWriter.reopen`` appends to it
as it is, so such a file reads and grows as before.

The pipeline always sees radial distance: a recording of a z-depth device (an Azure
Kinect's frames, a ROS depth image; ``distance_kind = "z"``) stores its frames as the
device gave them, and the reader converts them per pixel through the undistorted ray
(``tofpose.core.depth.radial_from_z``), so ``Recording.frame`` and ``block`` return
radial distances and ``Recording.camera`` says ``distance_kind = "radial"``
(``Recording.stored_distance_kind`` keeps what the file holds).
"""

from __future__ import annotations

import weakref
from collections.abc import Generator, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numpy as np

from tofpose.core.camera import SCALAR_FIELDS, CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.depth import radial_from_z
from tofpose.io.deflate_chunks import ChunkWriter, chunk_reader, chunk_writer
from tofpose.io.read_ahead import ReadAhead, cores_available

FORMAT = "tofpose-recording"
VERSION = 1
TRUTH_GROUP = "truth"
"""The pose a simulator rendered, per frame."""
REFERENCE_GROUP = "reference"
"""The lab's estimate of the pose (encoders + bench geometry), per frame."""
LEGACY_GROUPS = {REFERENCE_GROUP: ("lab_truth",)}
"""Older names of a pose group, read when the current one is absent."""
STAMP_DATASETS = ("frames/capture_ns", "frames/arrival_ns", "frames/pose_ready_ns")
"""The per-frame host stamps (module docstring), in the order of ``RecordingStamps``."""
STAMP_ANCHOR_ATTRS = ("monotonic_anchor_ns", "wall_anchor_ns")
"""``/frames``' attributes: one moment on the host's monotonic clock and in UTC ns."""
IMAGE_DATASETS = ("frames/gray", "frames/distance_mm")
"""The per-frame images, in the order ``Recording.block`` returns them."""
BLOCK_MIN_FRAMES = 32
"""``Recording.blocks`` reads at least this many frames at a time."""


class RecordingError(ValueError):
    """A recording that cannot be read: names the file and what is wrong."""


#: what ``RecordingWriter(compression=...)`` accepts: HDF5's built-in deflate, or none
COMPRESSIONS = ("gzip", None)


class RecordingWriter:
    """Append frames to a new recording. Use as a context manager.

    Frames are written in chunks of one frame (resizable datasets), so a recording
    interrupted part-way still holds every frame written before the interruption.
    ``compression="gzip"`` (the default) deflates each chunk at level 1 after HDF5's
    byte shuffle: both filters are built into every HDF5 library, so any HDF5 tool
    reads the file. On the simulator's range sweep the shuffle made the images 16 %
    smaller and reading them about a third faster than deflate alone (on one core,
    2.6 -> 1.7 ms a frame). ``compression=None`` stores the images uncompressed (about
    twice the size; reading them costs next to nothing).
    The distance images are stored as given, in ``camera.distance_kind`` (radial, or
    the z depth of a z-depth device: the reader converts those to radial).
    ``with_truth``: store ``/truth`` (the rendered pose); ``with_reference``: store
    ``/reference`` (the lab's estimate); ``with_lab_truth`` is its older name, the same.
    """

    def __init__(
        self,
        path: str | Path,
        camera: CameraModel,
        catalog: Catalog | None = None,
        *,
        with_truth: bool = False,
        with_reference: bool = False,
        with_lab_truth: bool = False,
        compression: str | None = "gzip",
    ) -> None:
        if compression not in COMPRESSIONS:
            # before the file is opened: a bad argument must not truncate a recording
            raise ValueError(
                f"compression must be one of {', '.join(map(repr, COMPRESSIONS))}, "
                f"got {compression!r}"
            )
        self.path = Path(path)
        self.camera = camera
        self._writers: tuple[ChunkWriter | None, ChunkWriter | None] | None = None
        self._f = h5py.File(self.path, "w")
        f = self._f
        f.attrs["format"] = FORMAT
        f.attrs["version"] = VERSION
        cam = f.create_group("camera")
        for k in SCALAR_FIELDS:
            cam.attrs[k] = getattr(camera, k)
        if camera.unwrapped_range_mm is not None:
            cam.attrs["unwrapped_range_mm"] = camera.unwrapped_range_mm
        cam.attrs["dist"] = np.asarray(camera.dist, float)
        cam.attrs["name"] = camera.name
        if catalog is not None:
            f.create_group("catalog").attrs["json"] = catalog.to_json()
        h, w = camera.height, camera.width
        fr = f.create_group("frames")
        opts: dict = {}
        if compression == "gzip":
            opts = {"compression": "gzip", "compression_opts": 1, "shuffle": True}
        self._gray = fr.create_dataset(
            "gray", (0, h, w), np.uint16, maxshape=(None, h, w), chunks=(1, h, w), **opts
        )
        self._dist = fr.create_dataset(
            "distance_mm", (0, h, w), np.float32, maxshape=(None, h, w), chunks=(1, h, w), **opts
        )
        self._time = fr.create_dataset("time_s", (0,), np.float64, maxshape=(None,), chunks=(1024,))
        self._truth = _pose_datasets(f, TRUTH_GROUP) if with_truth else None
        with_reference = with_reference or with_lab_truth
        self._reference = _pose_datasets(f, REFERENCE_GROUP) if with_reference else None
        self.n = 0

    def append(
        self,
        gray: np.ndarray,
        distance_mm: np.ndarray,
        time_s: float,
        R_camera_target: np.ndarray | None = None,
        t_camera_target_mm: np.ndarray | None = None,
        *,
        lab_R_camera_target: np.ndarray | None = None,
        lab_t_camera_target_mm: np.ndarray | None = None,
    ) -> None:
        """Add one frame; the truth (``R_camera_target``, ``t_camera_target_mm``) is
        required iff the writer was opened ``with_truth``, the reference
        (``lab_R_camera_target``, ``lab_t_camera_target_mm``) iff ``with_reference``."""
        shape = (self.camera.height, self.camera.width)
        if gray.shape != shape or distance_mm.shape != shape:
            raise ValueError(f"frame shapes {gray.shape}, {distance_mm.shape} != camera {shape}")
        n = self.n
        for ds in (self._gray, self._dist, self._time):
            ds.resize(n + 1, axis=0)
        if self._writers is None:  # the images' chunks deflated by ISA-L where it can
            self._writers = (chunk_writer(self._gray), chunk_writer(self._dist))
        for ds, writer, image, dtype in (
            (self._gray, self._writers[0], gray, np.uint16),
            (self._dist, self._writers[1], distance_mm, np.float32),
        ):
            if writer is None:
                ds[n] = image.astype(dtype)
            else:
                writer.write(n, image.astype(dtype))
        self._time[n] = time_s
        for name, datasets, R, t in (
            ("truth", self._truth, R_camera_target, t_camera_target_mm),
            ("reference", self._reference, lab_R_camera_target, lab_t_camera_target_mm),
        ):
            if datasets is None:
                continue
            if R is None or t is None:
                raise ValueError(f"this recording stores {name}: pass R and t for every frame")
            for ds, value in zip(datasets, (R, t), strict=True):
                ds.resize(n + 1, axis=0)
                ds[n] = value
        self.n += 1

    @classmethod
    def reopen(cls, path: str | Path) -> RecordingWriter:
        """Continue an existing recording (append mode); ``RecordingError`` if the file is
        not one of ours or lacks a dataset the writer needs."""
        path = Path(path)
        try:
            f = h5py.File(path, "a")
        except OSError as exc:
            raise RecordingError(f"{path}: cannot open for appending ({exc})") from exc
        try:
            if f.attrs.get("format") != FORMAT:
                raise RecordingError(f"{path}: not a tofpose recording")
            for ds in ("frames/gray", "frames/distance_mm", "frames/time_s"):
                if ds not in f:
                    raise RecordingError(f"{path}: missing dataset /{ds}")
            self = cls.__new__(cls)
            self.path, self._f = path, f
            self._writers = None
            self.camera = _camera_from_attrs(f["camera"].attrs, path)
            self._gray, self._dist = f["frames/gray"], f["frames/distance_mm"]
            self._time = f["frames/time_s"]
            self._truth = _existing_pose_datasets(f, TRUTH_GROUP)
            self._reference = _existing_pose_datasets(f, REFERENCE_GROUP)
            self.n = int(self._time.shape[0])
            return self
        except BaseException:
            f.close()
            raise

    def truncate(self, n: int) -> None:
        """Drop every frame from index ``n`` on (e.g. an aborted batch of frames)."""
        if not 0 <= n <= self.n:
            raise ValueError(f"cannot truncate a recording of {self.n} frames to {n}")
        datasets = [self._gray, self._dist, self._time]
        for group in (self._truth, self._reference):
            if group is not None:
                datasets += list(group)
        for ds in datasets:
            ds.resize(n, axis=0)
        self.n = n

    def flush(self) -> None:
        self._f.flush()

    def close(self) -> None:
        if self._f.id.valid:
            self._f.close()

    def __enter__(self) -> RecordingWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _pose_datasets(f: h5py.File, group: str) -> tuple[h5py.Dataset, h5py.Dataset]:
    """Resizable (N, 3, 3) rotation and (N, 3) translation datasets under ``group``."""
    g = f.create_group(group)
    R = g.create_dataset(
        "R_camera_target", (0, 3, 3), np.float64, maxshape=(None, 3, 3), chunks=(256, 3, 3)
    )
    t = g.create_dataset(
        "t_camera_target_mm", (0, 3), np.float64, maxshape=(None, 3), chunks=(256, 3)
    )
    return R, t


def _camera_from_attrs(attrs, path=None) -> CameraModel:
    """The CameraModel stored in /camera's attributes; RecordingError if invalid."""
    cam_attrs = {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in attrs.items()}
    for key in ("name", "distance_kind"):
        if isinstance(cam_attrs.get(key), bytes):
            cam_attrs[key] = cam_attrs[key].decode()
    try:
        return CameraModel.from_dict(cam_attrs)
    except ValueError as exc:
        raise RecordingError(f"{path}: /camera attributes are invalid ({exc})") from exc


def _stored_group(f: h5py.File, group: str) -> str | None:
    """The name ``group`` is stored under: itself, or an older name of it
    (``LEGACY_GROUPS``); None when the file has neither."""
    for name in (group, *LEGACY_GROUPS.get(group, ())):
        if name in f:
            return name
    return None


def _existing_pose_datasets(f: h5py.File, group: str):
    """``group``'s (R, t) datasets to append to, under its current or older name."""
    name = _stored_group(f, group)
    if name is None:
        return None
    return f[f"{name}/R_camera_target"], f[f"{name}/t_camera_target_mm"]


def _read_poses(f: h5py.File, group: str, n: int, path) -> tuple[np.ndarray, np.ndarray] | None:
    """(R (N, 3, 3), t (N, 3)) of ``/group`` (or of its older name, ``LEGACY_GROUPS``),
    None if absent; RecordingError if malformed."""
    stored = _stored_group(f, group)
    if stored is None:
        return None
    group = stored
    if f"{group}/R_camera_target" not in f or f"{group}/t_camera_target_mm" not in f:
        raise RecordingError(f"{path}: /{group} needs both R_camera_target and t_camera_target_mm")
    R = f[f"{group}/R_camera_target"][...]
    t = f[f"{group}/t_camera_target_mm"][...]
    if R.shape != (n, 3, 3) or t.shape != (n, 3):
        raise RecordingError(
            f"{path}: /{group} shapes {R.shape}, {t.shape} do not match {n} frames"
        )
    return R, t


@dataclass(frozen=True)
class RecordingStamps:
    """A live recording's per-frame stamps: ndarrays of shape (N,), int64 ns on the
    recording host's monotonic clock; ``wall_ns`` turns any of them into UTC ns."""

    capture_ns: np.ndarray
    arrival_ns: np.ndarray
    pose_ready_ns: np.ndarray
    monotonic_anchor_ns: int
    wall_anchor_ns: int

    def wall_ns(self, stamps_ns: np.ndarray) -> np.ndarray:
        """UTC ns (Unix epoch) of monotonic stamps: ndarray of the same shape."""
        return np.asarray(stamps_ns, np.int64) - self.monotonic_anchor_ns + self.wall_anchor_ns


@dataclass
class Recording:
    """An open recording (read-only). Frames are read lazily; use as a context manager.

    camera : CameraModel (``distance_kind`` "radial": what ``frame`` and ``block``
    return); catalog : Catalog or None; n_frames : int;
    time_s : ndarray (N,); truth_R : ndarray (N, 3, 3) or None; truth_t_mm : (N, 3) or None.
    reference_R, reference_t_mm : the lab's reference (``/reference``, or ``/lab_truth`` in
    older files), same shapes, or None; ``lab_truth_R``, ``lab_truth_t_mm`` are their
    older names.
    stored_distance_kind : "radial" or "z": what /frames/distance_mm holds (z depth is
    converted to radial distance as frames are read).
    wall_time_ns : (N,) int64 the host's wall clock (Unix ns) when each frame was
    captured (``/frames/wall_time_ns``, written by the server's recordings), or None
    when the file has none or not for every frame (``time_s`` is the device's clock).
    stamps : the live stream's capture, arrival and pose-ready stamps per frame
    (``RecordingStamps``), or None when the file has none or not for every frame.
    """

    path: Path
    camera: CameraModel
    catalog: Catalog | None
    n_frames: int
    time_s: np.ndarray
    truth_R: np.ndarray | None
    truth_t_mm: np.ndarray | None
    _file: h5py.File
    reference_R: np.ndarray | None = None
    reference_t_mm: np.ndarray | None = None
    stored_distance_kind: str = "radial"
    _stored_camera: CameraModel | None = None
    wall_time_ns: np.ndarray | None = None
    stamps: RecordingStamps | None = None
    _read_aheads: weakref.WeakSet = field(default_factory=weakref.WeakSet, repr=False)
    _readers: dict = field(default_factory=dict, repr=False)

    def _images(self, name: str, start: int, stop: int, single: bool = False) -> np.ndarray:
        """Frames [start, stop) of the image dataset ``name``: by its chunks, inflated
        with ISA-L where that reads it exactly (``tofpose.io.deflate_chunks``), else by
        h5py; the same bytes either way. ``single``: one frame of a sequence read frame
        by frame, left to h5py (and its chunk cache) where a chunk holds several."""
        if name not in self._readers:
            self._readers[name] = chunk_reader(self._file[name])
        reader = self._readers[name]
        if reader is None or (single and reader.frames_per_chunk > 1):
            return self._file[name][start:stop]
        return reader.read(start, stop)

    @property
    def lab_truth_R(self) -> np.ndarray | None:
        """The older name of ``reference_R``."""
        return self.reference_R

    @property
    def lab_truth_t_mm(self) -> np.ndarray | None:
        """The older name of ``reference_t_mm``."""
        return self.reference_t_mm

    def _radial(self, distance_mm: np.ndarray) -> np.ndarray:
        """Stored distances (H, W) or (n, H, W) as radial distances."""
        if self.stored_distance_kind != "z":
            return distance_mm
        return radial_from_z(distance_mm, self._stored_camera or self.camera)

    def frame(self, i: int) -> tuple[np.ndarray, np.ndarray, float]:
        """(gray (H, W) uint16, distance (H, W) float32, time_s) of frame i."""
        if not 0 <= i < self.n_frames:
            raise IndexError(f"frame {i} out of range 0..{self.n_frames - 1}")
        try:
            g = self._images("frames/gray", i, i + 1, single=True)[0]
            d = self._images("frames/distance_mm", i, i + 1, single=True)[0]
        except (OSError, KeyError) as exc:
            raise RecordingError(f"{self.path}: frame {i} cannot be read ({exc})") from exc
        return g, self._radial(d), float(self.time_s[i])

    def frames(self) -> Iterator[tuple[np.ndarray, np.ndarray, float]]:
        for i in range(self.n_frames):
            yield self.frame(i)

    @property
    def frames_per_chunk(self) -> int:
        """Frames in one HDF5 chunk of /frames/gray (1 for a contiguous dataset): read
        blocks aligned to it and each chunk is decompressed once."""
        chunks = self._file["frames/gray"].chunks
        return int(chunks[0]) if chunks else 1

    def block(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Frames [start, stop) in one read: gray (n, H, W) uint16, distance (n, H, W)
        float32, time_s (n,). ``RecordingError`` naming the first frame of them that
        cannot be read."""
        if not 0 <= start <= stop <= self.n_frames:
            raise IndexError(f"frames {start}..{stop} out of range 0..{self.n_frames}")
        try:
            g = self._images("frames/gray", start, stop)
            d = self._images("frames/distance_mm", start, stop)
        except (OSError, KeyError) as exc:
            i = self._first_unreadable(start, stop)
            raise RecordingError(f"{self.path}: frame {i} cannot be read ({exc})") from exc
        return g, self._radial(d), np.asarray(self.time_s[start:stop], float)

    def _first_unreadable(self, start: int, stop: int) -> int:
        """The first of frames [start, stop) that cannot be read on its own (``start``
        when each can): the frame a failed block read names."""
        for i in range(start, stop):
            try:
                for name in IMAGE_DATASETS:
                    self._file[name][i]
            except (OSError, KeyError):
                return i
        return start

    def block_spans(self, start: int = 0, stop: int | None = None) -> list[tuple[int, int]]:
        """The [a, b) spans ``blocks`` reads over [start, stop): aligned to the file's
        chunks (``frames_per_chunk``); the first one chunk, each next one twice as long
        until the next multiple of ``BLOCK_MIN_FRAMES`` frames (rounded up to whole
        chunks) is at most two of them away, then from multiple to multiple. The ramp
        lets the caller start on the first frames while the reader thread reads the
        next ones: a whole first block read before any work cost each re-processed
        chunk ~6 % of its time."""
        stop = self.n_frames if stop is None else stop
        per_chunk = self.frames_per_chunk
        step = per_chunk * max(1, -(-BLOCK_MIN_FRAMES // per_chunk))
        spans, a, size, ramp = [], start, per_chunk, True
        while a < stop:
            edge = (a // step + 1) * step
            if ramp and edge - a > 2 * size:  # the ramp: whole chunks, doubling
                b = a // per_chunk * per_chunk + size
                size *= 2
            else:  # to the next edge (the ramp's last read too)
                b, ramp = edge, False
            spans.append((a, min(stop, b)))
            a = min(stop, b)
        return spans

    def blocks(
        self, start: int = 0, stop: int | None = None, *, read_ahead: bool | None = None
    ) -> Generator[tuple[int, tuple[np.ndarray, np.ndarray, np.ndarray]], None, None]:
        """(first frame, ``block``) over [start, stop) in reads aligned to the file's
        chunks (``block_spans``); ``close()`` it to stop early.

        ``read_ahead``: read the next block in a reader thread while the caller works on
        this one (``tofpose.io.read_ahead``: the caller should make no h5py call of its
        own meanwhile, or it waits for the read); None (the default): when there is more
        than one block and this process may use more than one core (on one core the
        thread has nothing to overlap). Stopping early, or closing the recording, stops
        the thread.
        """
        spans = self.block_spans(start, stop)
        if read_ahead is None:
            read_ahead = len(spans) > 1 and cores_available() > 1
        if not read_ahead:
            for a, b in spans:
                yield a, self.block(a, b)
            return
        reader = ReadAhead(self.block, spans)
        self._read_aheads.add(reader)
        with reader:
            done = 0
            for block in reader:
                yield spans[done][0], block
                done += 1
        if done < len(spans):  # the reader was stopped by ``close``
            raise RecordingError(f"{self.path}: closed before frame {spans[done][0]} was read")

    @property
    def reading_ahead(self) -> bool:
        """Whether a reader thread of ``blocks`` is there now."""
        return any(reader.running for reader in list(self._read_aheads))

    def close(self) -> None:
        """Stop any reader thread of ``blocks`` (after its read in flight), then close
        the file."""
        for reader in list(self._read_aheads):
            reader.close()
        if self._file.id.valid:
            self._file.close()

    def __enter__(self) -> Recording:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _wall_times(f: h5py.File, n: int) -> np.ndarray | None:
    """``/frames/wall_time_ns`` (n,) int64 when present for every frame (positive and
    non-decreasing), else None."""
    ds = f.get("frames/wall_time_ns")
    if ds is None or ds.shape != (n,) or n == 0:
        return None
    ns = np.asarray(ds[...], dtype=np.int64)
    if not (ns > 0).all() or (np.diff(ns) < 0).any():
        return None
    return ns


def _stamps(f: h5py.File, n: int) -> RecordingStamps | None:
    """``STAMP_DATASETS`` and their anchor when all are there for every frame, else
    None (an older recording, or one cut off part-way through a frame)."""
    frames = f["frames"]
    if any(f.get(name) is None or f[name].shape != (n,) for name in STAMP_DATASETS):
        return None
    if any(a not in frames.attrs for a in STAMP_ANCHOR_ATTRS):
        return None
    capture, arrival, pose_ready = (np.asarray(f[name][...], np.int64) for name in STAMP_DATASETS)
    mono, wall = (int(frames.attrs[a]) for a in STAMP_ANCHOR_ATTRS)
    return RecordingStamps(capture, arrival, pose_ready, mono, wall)


def open_recording(path: str | Path) -> Recording:
    """Open and validate a recording; raises ``RecordingError`` naming the problem."""
    path = Path(path)
    if not path.exists():
        raise RecordingError(f"{path}: no such file")
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise RecordingError(f"{path}: not a readable HDF5 file ({exc})") from exc
    try:
        if f.attrs.get("format") != FORMAT:
            raise RecordingError(
                f"{path}: not a tofpose recording (format attribute is {f.attrs.get('format')!r})"
            )
        version = int(f.attrs.get("version", -1))
        if version != VERSION:
            raise RecordingError(
                f"{path}: unsupported recording version {version} (expected {VERSION})"
            )
        if "camera" not in f:
            raise RecordingError(f"{path}: missing the /camera group")
        camera = _camera_from_attrs(f["camera"].attrs, path)
        catalog = None
        if "catalog" in f:
            try:
                catalog = Catalog.from_json(str(f["catalog"].attrs["json"]))
            except (KeyError, ValueError) as exc:
                raise RecordingError(f"{path}: /catalog is invalid ({exc})") from exc
        for name in ("frames/gray", "frames/distance_mm", "frames/time_s"):
            if name not in f:
                raise RecordingError(f"{path}: missing dataset /{name}")
        g, d, t = f["frames/gray"], f["frames/distance_mm"], f["frames/time_s"]
        shape = (camera.height, camera.width)
        for ds in (g, d):
            if ds.ndim != 3 or ds.shape[1:] != shape:
                raise RecordingError(
                    f"{path}: /{ds.name.lstrip('/')} has shape {ds.shape}, "
                    f"expected (N, {shape[0]}, {shape[1]})"
                )
        if g.dtype != np.uint16:
            raise RecordingError(f"{path}: /frames/gray must be uint16, is {g.dtype}")
        if d.dtype.kind != "f":
            raise RecordingError(f"{path}: /frames/distance_mm must be float, is {d.dtype}")
        n = g.shape[0]
        if d.shape[0] != n or t.shape != (n,):
            raise RecordingError(
                f"{path}: frame counts disagree (gray {n}, distance {d.shape[0]}, "
                f"time_s {t.shape[0]})"
            )
        truth = _read_poses(f, TRUTH_GROUP, n, path)
        lab = _read_poses(f, REFERENCE_GROUP, n, path)
        truth_R, truth_t = truth if truth is not None else (None, None)
        lab_R, lab_t = lab if lab is not None else (None, None)
        # z-depth frames are read as radial (Recording._radial): the camera says so
        stored_kind = camera.distance_kind
        return Recording(
            path,
            replace(camera, distance_kind="radial"),
            catalog,
            n,
            t[...],
            truth_R,
            truth_t,
            f,
            lab_R,
            lab_t,
            stored_distance_kind=stored_kind,
            _stored_camera=camera,
            wall_time_ns=_wall_times(f, n),
            stamps=_stamps(f, n),
        )
    except RecordingError:
        f.close()
        raise
    except (OSError, KeyError) as exc:
        f.close()
        raise RecordingError(f"{path}: corrupt recording ({exc})") from exc
