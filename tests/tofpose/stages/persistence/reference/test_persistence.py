"""The reference statement of §3.4's persistence against known truth."""

from __future__ import annotations

import numpy as np

from tofpose.stages.persistence.reference import persistence as reference


def test_centroids_are_consistent_when_most_lie_within_the_tolerance():
    prev = np.array([[10.0, 10.0], [30.0, 12.0], [50.0, 40.0]])
    assert reference.centroids_consistent(prev + 0.2, prev, 0.35)
    assert not reference.centroids_consistent(prev + 0.5, prev, 0.35)  # median 0.71 px
    moved = prev.copy()
    moved[:2] += 10.0  # two of three jumped: fewer than half have a neighbour
    assert not reference.centroids_consistent(moved, prev, 0.35)
    assert reference.centroids_consistent(np.vstack((prev, [[np.nan, np.nan]])), prev, 0.35)


def test_ranges_are_inconsistent_when_every_marker_moved_beyond_its_noise():
    rng = np.random.default_rng(0)
    prev = rng.normal(3000.0, 3.0, 400).astype(np.float32)
    blobs = [np.arange(j * 50, j * 50 + 50) for j in range(8)]
    still = (prev + rng.normal(0.0, 3.0, 400)).astype(np.float32)
    assert reference.ranges_consistent(still, prev, blobs)
    assert not reference.ranges_consistent(still + 6.0, prev, blobs)
    assert reference.ranges_consistent(np.full(400, np.nan, np.float32), prev, blobs)


def test_a_static_stream_is_averaged_and_a_transient_blob_fails_the_counter():
    h = reference.History(k_frames=3, c_min=2, motion_tolerance_px=0.35)
    gray = np.full((4, 5), 100.0, np.float32)
    blob = np.array([6, 7])
    for level in (100.0, 200.0):
        out = h.combine([blob], np.array([[1.5, 1.0]]), gray * level / 100, gray * 0 + level)
    assert out.frames_used == 2 and not out.motion and out.keep.tolist() == [True]
    assert out.mean_gray[0, 0] == 150.0 and out.median_distance[0, 0] == 150.0
    transient = np.array([18])
    out = h.combine([blob, transient], np.array([[1.5, 1.0], [3.0, 3.0]]), gray, gray)
    assert out.frames_used == 3 and out.keep.tolist() == [True, False]
    out = h.combine([blob], np.array([[4.0, 3.0]]), gray, gray)  # the scene moved
    assert out.motion and out.frames_used == 1 and len(h.entries) == 1
