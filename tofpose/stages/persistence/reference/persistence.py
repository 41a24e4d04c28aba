"""§3.4's multi-frame persistence as stated, with our two tests of a static scene: the
history of the last K - 1 frames, which of them are consistent with the current one, the
counter image C (how many of the combined frames hold each pixel in a candidate blob),
the mean intensity I-bar and the temporal median distance D-bar.

A frame enters the history as (centroids (n, 2) px, blob mask (H * W,) bool, gray (H, W)
float32, distance (H, W) float32 mm). Blobs are flat pixel index arrays (P,).
"""

from __future__ import annotations

import warnings
from collections import deque
from typing import NamedTuple

import numpy as np

from tofpose.stages.extraction.constants import MAD_TO_SIGMA
from tofpose.stages.persistence.constants import (
    RANGE_TEST_CLIP,
    RANGE_TEST_MAX_PIXELS,
    RANGE_TEST_MIN_PIXELS,
    RANGE_TEST_Z,
)


class Entry(NamedTuple):
    """One frame as the history keeps it."""

    centroids: np.ndarray
    mask: np.ndarray
    gray: np.ndarray
    distance: np.ndarray


class Combined(NamedTuple):
    """What persistence gives a frame: keep (n,) bool (C >= C_min, or every blob while
    fewer than C_min frames are combined), mean_gray I-bar and median_distance D-bar
    (H, W) float32 over the combined frames, frames_used, motion (the history was cut)."""

    keep: np.ndarray
    mean_gray: np.ndarray
    median_distance: np.ndarray
    frames_used: int
    motion: bool


def centroids_consistent(current, previous, tol_px: float) -> bool:
    """The same static scene by its centroids (n, 2), (m, 2): at least half of the
    current centroids (rounded up, at least one) have a previous one within max(4 tol,
    2 px), and the median of those nearest distances is at most tol. NaN centroids have
    no neighbour."""
    current, previous = np.asarray(current, float), np.asarray(previous, float)
    if len(current) == 0 or len(previous) == 0:
        return len(current) == len(previous)
    d = np.hypot(
        current[:, None, 0] - previous[None, :, 0], current[:, None, 1] - previous[None, :, 1]
    )
    nearest = np.min(np.where(np.isnan(d), np.inf, d), axis=1)
    near = nearest[nearest < max(4 * tol_px, 2.0)]
    if len(near) < max(1, int(np.ceil(0.5 * len(current)))):
        return False
    return bool(np.median(near) <= tol_px)


def ranges_consistent(current, previous, blobs, z: float = RANGE_TEST_Z) -> bool:
    """The same static scene by its ranges: per blob (every k-th pixel, k = P // 48, at
    least 5 valid in both frames) t = median(delta) / (1.4826 MAD(delta) sqrt(pi / 2) /
    sqrt(n)); consistent when sum min(t^2, 9) is within chi^2 of the number of blobs
    tested at the normal quantile z (Wilson-Hilferty), or no blob can be tested."""
    cur, prev = np.asarray(current).reshape(-1), np.asarray(previous).reshape(-1)
    stat, tested = 0.0, 0
    for pixels in blobs:
        step = max(1, len(pixels) // RANGE_TEST_MAX_PIXELS)
        p = np.asarray(pixels)[::step]
        delta = cur[p].astype(float) - prev[p].astype(float)
        delta = delta[np.isfinite(delta)][: 2 * RANGE_TEST_MAX_PIXELS]
        if len(delta) < RANGE_TEST_MIN_PIXELS:
            continue
        med = np.median(delta)
        se = MAD_TO_SIGMA * np.median(np.abs(delta - med)) * np.sqrt(0.5 * np.pi / len(delta))
        if se <= 0.0:
            continue
        stat += min((med / se) ** 2, RANGE_TEST_CLIP)
        tested += 1
    if tested == 0:
        return True
    c = 2.0 / (9.0 * tested)
    return bool(stat <= tested * (1.0 - c + z * np.sqrt(c)) ** 3)


class History:
    """The persistence history of K - 1 frames (``PersistenceConfig``'s k_frames, c_min,
    motion_tolerance_px)."""

    def __init__(self, k_frames: int, c_min: int, motion_tolerance_px: float) -> None:
        self.c_min, self.motion_tolerance_px = c_min, motion_tolerance_px
        self.entries: deque[Entry] = deque(maxlen=max(k_frames - 1, 0))

    def combine(self, blobs, centroids, gray, distance) -> Combined:
        """The frame (blobs: pixel arrays; centroids (n, 2)) with its consistent history:
        the newest history frames back to the first that fails either test (motion: the
        older ones are forgotten); then the frame joins the history."""
        used = []
        motion = False
        for entry in reversed(self.entries):
            if centroids_consistent(
                centroids, entry.centroids, self.motion_tolerance_px
            ) and ranges_consistent(distance, entry.distance, blobs):
                used.append(entry)
            else:
                motion = True
                break
        if motion:
            kept = list(reversed(used))
            self.entries.clear()
            self.entries.extend(kept)
        mask = np.zeros(gray.size, bool)
        for pixels in blobs:
            mask[pixels] = True
        self.entries.append(Entry(np.asarray(centroids, float), mask, gray, distance))
        frames = 1 + len(used)
        keep = np.ones(len(blobs), bool)
        if frames == 1 or not len(blobs):
            return Combined(keep, gray, distance, frames, motion)
        if frames >= self.c_min:
            counter = 1 + sum(e.mask.astype(int) for e in used)  # C at every pixel
            keep = np.array([np.median(counter[p]) >= self.c_min for p in blobs])
        older_sum = np.zeros_like(gray, dtype=np.float32)
        for e in used:  # newest first, in float32
            older_sum += e.gray
        mean_gray = (np.asarray(gray, np.float32) + older_sum) / np.float32(frames)
        stack_d = np.stack([distance] + [e.distance for e in used])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # pixels NaN in every frame
            median_distance = np.nanmedian(stack_d, axis=0).astype(np.float32)
        return Combined(keep, mean_gray, median_distance, frames, motion)
