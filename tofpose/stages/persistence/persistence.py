"""Multi-frame persistence (§3.4) that never smears a moving scene.

The paper keeps a counter image C (frames in which each pixel belonged to a candidate
blob), drops pixels with C < C_min, and averages intensity and takes the temporal median
of distance over the last K frames. Averaging frames of a moving target would report a
stale, smeared pose, so (ours) the history is cut at the first frame whose blobs do not
line up with the current ones within ``motion_tolerance_px``; only consistent frames are
combined, and a moving scene degrades gracefully to single-frame measurement.
"""

from __future__ import annotations

import hashlib
from collections import deque
from dataclasses import dataclass

import numpy as np

from tofpose.config import PersistenceConfig
from tofpose.core.camera import CameraModel
from tofpose.core.records import FrameRecord, PersistenceHistory, camera_record
from tofpose.stages.extraction.extraction import CUT_FROM_MERGED, Blob, pixel_lists
from tofpose.stages.persistence.kernels.measure import persist_and_measure
from tofpose.stages.persistence.kernels.persistence import pixel_mask
from tofpose.stages.persistence.records import BlobLists


@dataclass
class _Entry:
    centroids: np.ndarray  # (n, 2) single-frame centroids
    mask: np.ndarray  # (H * W,) bool, candidate-blob pixels
    gray: np.ndarray  # (H, W) float32
    distance: np.ndarray  # (H, W) float32
    digest: bytes | None = None  # of the four arrays, once asked for (``update_digest``)

    def content_digest(self) -> bytes:
        """SHA-256 of the entry's arrays (shapes and bytes), computed once: an entry is
        never changed after it enters the history, and the digest of a pipeline's state
        is asked for on every frame of a re-processed chunk's warm-up, where each entry
        stays for K - 1 frames: hashed once, not K - 1 times. (SHA-256 runs at about
        twice blake2b's speed on CPUs with SHA instructions, as this one, ~0.3 ms for a
        320 x 240 entry; at about half without them.)"""
        if self.digest is None:
            h = hashlib.sha256()
            for a in (self.centroids, self.mask, self.gray, self.distance):
                h.update(str(a.shape).encode())
                h.update(np.ascontiguousarray(a).tobytes())
            self.digest = h.digest()
        return self.digest


@dataclass
class PersistenceInfo:
    frames_used: int
    motion: bool
    dropped_blobs: int


def blob_lists(blobs: list[Blob]) -> BlobLists:
    """The blobs as the compiled measurement takes them (a ``records.BlobLists``): flat
    pixel indices and starts (``pixel_lists``), boxes (n, 4) (x, y, w, h), single-frame
    centroids (n, 2) and whether each was cut out of a merged component (its source one
    of ``extraction.CUT_FROM_MERGED``)."""
    flat, starts = pixel_lists(blobs)
    return BlobLists(
        flat=flat,
        starts=starts,
        bbox=np.array([b.bbox for b in blobs], np.int64).reshape(-1, 4),
        centroids=np.array([b.centroid_uv for b in blobs], np.float64).reshape(-1, 2),
        split=np.array([b.source in CUT_FROM_MERGED for b in blobs], bool),
    )


class Persistence:
    """Counter image and temporal combination over the last K consistent frames."""

    def __init__(self, config: PersistenceConfig | None = None) -> None:
        self.config = config or PersistenceConfig()
        self._history: deque[_Entry] = deque(maxlen=max(self.config.k_frames - 1, 0))
        self._scratch: tuple[np.ndarray, np.ndarray] | None = None
        #: the history's (gray, distance, mask, centroids) tuples newest first, built
        #: once per change of the history (``history`` reads them every frame)
        self._newest_first: tuple[tuple, tuple, tuple, tuple] | None = None
        #: the padding's empty mask (H * W,) and centroids (0, 2), never written
        self._empty: tuple[np.ndarray, np.ndarray] | None = None

    def scratch(self, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The two (H, W) float32 frames the compiled measurement writes I-bar and D-bar
        into where they are read (``kernels.measure.persist_and_measure``), allocated
        once per image size and lent to every frame."""
        if self._scratch is None or self._scratch[0].shape != shape:
            self._scratch = (np.zeros(shape, np.float32), np.zeros(shape, np.float32))
        return self._scratch

    def reset(self) -> None:
        self._history.clear()
        self._newest_first = None

    def update_digest(self, h) -> None:
        """Feed the history (every entry's digest of its arrays, oldest first) into the
        hashlib object ``h`` (``PosePipeline.state_digest``)."""
        h.update(len(self._history).to_bytes(2, "little"))
        for e in self._history:
            h.update(e.content_digest())

    def snapshot(self) -> list:
        """The history as it is (for ``restore``: a pass that is abandoned after ``apply``
        must not leave its frame in the history twice)."""
        return list(self._history)

    def restore(self, snapshot: list) -> None:
        self._history.clear()
        self._history.extend(snapshot)
        self._newest_first = None

    def measure(
        self,
        blobs: list[Blob],
        gray: np.ndarray,
        distance: np.ndarray,
        camera: CameraModel,
        background: float,
        dark: float = float("nan"),
    ) -> tuple[list[Blob], np.ndarray, np.ndarray, PersistenceInfo]:
        """The §3.4 combination (``tofpose.stages.persistence.reference.persistence.History``)
        followed by
        ``extraction.measure_blobs`` on the kept blobs, in one
        compiled call (``kernels.measure.persist_and_measure``): the kept blobs with
        their centroids (Eq. 19) and ranges (Eq. 20) measured on the combined frames,
        the combined frames (I-bar, D-bar) and what was combined. ``background``,
        ``dark`` : the frame's background and no-return levels, counts. The combined
        frames are defined where the next steps read them, inside the blobs' boxes grown
        by 2 px (I-bar) and at the kept blobs' pixels (D-bar), and are reused by the next
        frame (``scratch``)."""
        lists = blob_lists(blobs)
        frame = FrameRecord(
            gray=gray, distance=distance, background=float(background), dark=float(dark)
        )
        out = persist_and_measure(frame, lists, self.history(gray, distance), camera_record(camera))
        self.commit(lists.centroids, lists.flat, gray, distance, out.n_used, out.motion)
        kept = [
            b.with_values(
                centroid_uv=out.uv[j], distance_mm=float(out.rho[j]), mixing=out.mixing[j]
            )
            for j, b in enumerate(blobs)
            if out.keep[j]
        ]
        info = PersistenceInfo(1 + out.n_used, out.motion, len(blobs) - len(kept))
        return kept, out.mean_gray, out.med_distance, info

    def history(self, gray: np.ndarray, distance: np.ndarray) -> PersistenceHistory:
        """The history newest first with the settings, as the kernels take it (a
        ``core.records.PersistenceHistory``): tuples of gray, distance, mask and
        centroids, each padded to K - 1 entries (at least one) with this frame's arrays
        (never read), the number of real entries, and the scratch frames (``scratch``)."""
        k = max(self.config.k_frames - 1, 1)
        newest_first = self._newest_first
        if newest_first is None:
            entries = list(reversed(self._history))
            newest_first = self._newest_first = (
                tuple([e.gray for e in entries]),
                tuple([e.distance for e in entries]),
                tuple([e.mask for e in entries]),
                tuple([e.centroids for e in entries]),
            )
        grays, distances, masks, centroids = newest_first
        n_frames = len(grays)
        pad = k - n_frames
        scratch_gray, scratch_distance = self.scratch(gray.shape)
        if pad:
            empty = self._empty
            if empty is None or empty[0].shape[0] != gray.size:
                empty = self._empty = (np.zeros(gray.size, bool), np.zeros((0, 2)))
            grays += (gray,) * pad
            distances += (distance,) * pad
            masks += (empty[0],) * pad
            centroids += (empty[1],) * pad
        return PersistenceHistory(
            gray=grays,
            distance=distances,
            mask=masks,
            centroids=centroids,
            n_frames=n_frames,
            motion_tolerance_px=float(self.config.motion_tolerance_px),
            c_min=int(self.config.c_min),
            scratch_gray=scratch_gray,
            scratch_distance=scratch_distance,
        )

    def commit(
        self,
        centroids: np.ndarray,
        pixels: np.ndarray,
        gray: np.ndarray,
        distance: np.ndarray,
        n_used: int,
        motion: bool,
    ) -> None:
        """Record a frame combined by ``track_frame`` as ``apply`` would have: with
        motion, only the ``n_used`` newest entries stay; then this frame is appended.
        centroids : (n, 2) its blobs' centroids; pixels : their flat pixel indices."""
        if motion:
            keep = list(self._history)[len(self._history) - n_used :] if n_used else []
            self._history.clear()
            self._history.extend(keep)
            self._newest_first = None
        mask = pixel_mask(pixels, gray.size)
        self._history.append(_Entry(centroids, mask, gray, distance))
        newest_first = self._newest_first
        if newest_first is not None:  # this frame first, the oldest dropped as the deque did
            n = len(self._history)
            grays, distances, masks, centroid_sets = newest_first
            self._newest_first = (
                ((gray,) + grays)[:n],
                ((distance,) + distances)[:n],
                ((mask,) + masks)[:n],
                ((centroids,) + centroid_sets)[:n],
            )
