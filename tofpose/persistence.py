"""Multi-frame persistence (§3.4) that never smears a moving scene.

The paper keeps a counter image C (frames in which each pixel belonged to a candidate
blob), drops pixels with C < C_min, and averages intensity and takes the temporal median
of distance over the last K frames. Averaging frames of a moving target would report a
stale, smeared pose, so (ours) the history is cut at the first frame whose blobs do not
line up with the current ones within ``motion_tolerance_px``; only consistent frames are
combined, and a moving scene degrades gracefully to single-frame measurement.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from tofpose.extraction import Blob
from tofpose.kernels.persistence import column_medians
from tofpose.robust import median_1d


@dataclass(frozen=True)
class PersistenceConfig:
    """K frames of history, C_min frames of presence, and the motion gate (pixels)."""

    k_frames: int = 5
    c_min: int = 2
    motion_tolerance_px: float = 0.35

    def __post_init__(self) -> None:
        if self.k_frames < 1 or self.c_min < 1:
            raise ValueError("k_frames and c_min must be >= 1")


@dataclass
class _Entry:
    centroids: np.ndarray  # (n, 2) single-frame centroids
    mask: np.ndarray  # (H, W) bool, candidate-blob pixels
    gray: np.ndarray  # (H, W) float32
    distance: np.ndarray  # (H, W) float32


@dataclass
class PersistenceInfo:
    frames_used: int
    motion: bool
    dropped_blobs: int


def _consistent(current: np.ndarray, previous: np.ndarray, tol_px: float) -> bool:
    """Do two centroid sets (n, 2), (m, 2) describe the same static scene?"""
    if len(current) == 0 or len(previous) == 0:
        return len(current) == len(previous)
    d = np.linalg.norm(current[:, None, :] - previous[None, :, :], axis=-1)
    nn = d.min(axis=1)
    near = nn < max(4 * tol_px, 2.0)
    if near.sum() < max(1, int(np.ceil(0.5 * len(current)))):
        return False
    return median_1d(nn[near]) <= tol_px


def _mean_near_blobs(gray: np.ndarray, older: list[np.ndarray], blobs: list[Blob]):
    """I-bar (§3.4) where it is read: in each blob's box grown by 2 px (its centroid ring
    and range pixels); elsewhere this frame's gray. (H, W) like ``gray``; inside the boxes
    the same arithmetic as the full-frame mean, ``(gray + sum(older)) / n``."""
    n = 1 + len(older)
    h, w = gray.shape
    if not blobs:
        return (gray + sum(older)) / n
    out = np.array(gray, dtype=np.result_type(gray.dtype, np.float32))
    for b in blobs:
        x, y, bw, bh = b.bbox
        sl = np.s_[max(y - 2, 0) : min(y + bh + 2, h), max(x - 2, 0) : min(x + bw + 2, w)]
        out[sl] = (gray[sl] + sum(o[sl] for o in older)) / n
    return out


class Persistence:
    """Counter image and temporal combination over the last K consistent frames."""

    def __init__(self, config: PersistenceConfig | None = None) -> None:
        self.config = config or PersistenceConfig()
        self._history: deque[_Entry] = deque(maxlen=max(self.config.k_frames - 1, 0))

    def reset(self) -> None:
        self._history.clear()

    def snapshot(self) -> list:
        """The history as it is (for ``restore``: a pass that is abandoned after ``apply``
        must not leave its frame in the history twice)."""
        return list(self._history)

    def restore(self, snapshot: list) -> None:
        self._history.clear()
        self._history.extend(snapshot)

    def apply(
        self, blobs: list[Blob], gray: np.ndarray, distance: np.ndarray
    ) -> tuple[list[Blob], np.ndarray, np.ndarray, PersistenceInfo]:
        """Combine the current frame with consistent history.

        Parameters
        ----------
        blobs : candidate blobs of this frame, with single-frame centroids.
        gray, distance : ndarray of shape (H, W), this frame.

        Returns
        -------
        kept : blobs passing the counter check C >= C_min (all blobs while fewer than
            C_min consistent frames exist, so a fresh or moving scene is still measured).
        mean_gray : (H, W) float32, mean intensity over the consistent frames (I-bar).
        median_distance : (H, W) float32, temporal median of distance (D-bar), computed
            at blob pixels; elsewhere this frame's distance.
        info : PersistenceInfo.
        """
        cfg = self.config
        h, w = gray.shape
        cur = np.array([b.centroid_uv for b in blobs]).reshape(-1, 2)
        mask = np.zeros(h * w, bool)
        for b in blobs:
            mask[b.pixels] = True
        mask = mask.reshape(h, w)

        used: list[_Entry] = []
        motion = False
        for entry in reversed(self._history):
            if _consistent(cur, entry.centroids, cfg.motion_tolerance_px):
                used.append(entry)
            else:
                motion = True
                break
        if motion:
            # Older frames show the scene elsewhere: forget them for good.
            keep = list(reversed(used))
            self._history.clear()
            self._history.extend(keep)
        self._history.append(_Entry(cur, mask, gray, distance))

        n = 1 + len(used)
        kept, dropped = blobs, 0
        mean_gray, med_dist = gray, distance
        if n > 1:
            if n >= cfg.c_min:
                kept = []
                # the counter image C, read only where it is used: at the blobs' pixels
                idx = np.concatenate([b.pixels for b in blobs]) if blobs else np.empty(0, int)
                count = mask.reshape(-1)[idx].astype(np.int32)
                for e in used:
                    count += e.mask.reshape(-1)[idx]
                ends = np.cumsum([len(b.pixels) for b in blobs])
                for b, end in zip(blobs, ends, strict=True):
                    c = count[end - len(b.pixels) : end]
                    if median_1d(c) >= cfg.c_min:
                        kept.append(b)
                    else:
                        dropped += 1
            mean_gray = _mean_near_blobs(gray, [e.gray for e in used], blobs)
            med_dist = distance.copy()
            if kept:
                idx = np.concatenate([b.pixels for b in kept])
                stack = np.stack(
                    [distance.reshape(-1)[idx]] + [e.distance.reshape(-1)[idx] for e in used]
                )
                med_dist.reshape(-1)[idx] = column_medians(stack.astype(np.float32, copy=False))
        return kept, mean_gray, med_dist, PersistenceInfo(n, motion, dropped)
