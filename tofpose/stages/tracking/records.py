"""The records of tracking mode's kernels (``kernels.tracking``, ``kernels.tracking_frame``)
and their reference statements, which return the same: the search windows, a window's
components as runs, and a tracked frame. ``typing.NamedTuple``s: numba compiles them as
tuples with named fields; each is built by keyword."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tofpose.core.records import Candidates
from tofpose.stages.pose.records import SolvedPairs


class Windows(NamedTuple):
    """Search windows around the m reflectors to track (``camera_windows``):
    ``catalog_index`` (m,) int64, ``bounds`` (m, 4) int64 [u0, u1) x [v0, v1) as (u0, u1,
    v0, v1), the predicted ``centres`` (m, 2) px and ``diameters_px`` (m,)."""

    catalog_index: np.ndarray
    bounds: np.ndarray
    centres: np.ndarray
    diameters_px: np.ndarray


class WindowRuns(NamedTuple):
    """The 8-connected components of a window's pixels at or above the threshold as runs
    (``_window_runs``): run q covers row ``row[q]`` (window coordinates), columns
    [``c0[q]``, ``c1[q]``), and belongs to component ``label[q]`` (runs in raster order,
    components numbered 1 .. ``n`` in the raster order of their first pixel); per
    component (index 0 .. n, 0 empty) its ``area``, the sums of its pixels' columns
    ``sum_u`` and rows ``sum_v``, and its ``box`` (x0, x1, y0, y1) inclusive, window
    coordinates."""

    row: np.ndarray
    c0: np.ndarray
    c1: np.ndarray
    label: np.ndarray
    n: int
    area: np.ndarray
    sum_u: np.ndarray
    sum_v: np.ndarray
    box: np.ndarray


class TrackedFrame(NamedTuple):
    """One tracking frame (``track_frame``): its outcome ``code`` (``constants.TRACKED``,
    or why the frame falls back to acquisition), the windows' blobs (``centroids`` (n, 2)
    their moment centroids, pixel lists ``flat``, ``starts``), what persistence combined
    (``n_used`` history frames; ``motion``: it cut the history), the blobs measured (a
    ``core.records.Candidates``: every one ranged, in window order, when tracked) and the
    pose of the known correspondences (``solved``, a ``pose.records.SolvedPairs``); what
    follows the step that set ``code`` is NaN."""

    code: int
    centroids: np.ndarray
    flat: np.ndarray
    starts: np.ndarray
    n_used: int
    motion: bool
    candidates: Candidates
    solved: SolvedPairs
