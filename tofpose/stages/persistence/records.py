"""The records of the measurement (``kernels.measure`` and its reference statement
``reference.measure``, which take and return the same): a frame's blobs, what persistence
combined and measured of them, and their measurement back-projected.
``typing.NamedTuple``s: numba compiles them as tuples with named fields; each is built
by keyword."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from tofpose.core.records import Candidates


class BlobLists(NamedTuple):
    """A frame's n blobs as the measurement reads them: ``flat`` (P,) int64 and ``starts``
    (n + 1,) int64, blob j's pixels (flat indices, raster order) being
    ``flat[starts[j]:starts[j + 1]]``; ``bbox`` (n, 4) int64 (x, y, w, h); ``centroids``
    (n, 2) their single-frame centroids (NaN allowed; the motion test reads them);
    ``split`` (n,) bool, cut out of a merged component."""

    flat: np.ndarray
    starts: np.ndarray
    bbox: np.ndarray
    centroids: np.ndarray
    split: np.ndarray


class PersistedBlobs(NamedTuple):
    """The blobs combined with the consistent history and measured
    (``persist_and_measure``): ``n_used`` history frames combined, ``motion`` (the
    history was cut), ``keep`` (n,) bool (counter C >= c_min), the combined frames
    ``mean_gray`` (I-bar) and ``med_distance`` (D-bar) ((H, W) float32), and of the kept
    blobs (NaN for the others) ``uv`` (n, 2) centroids, ``rho`` (n,) ranges and ``mixing``
    (n, ``extraction.constants.MIX_FIELDS``) their mixing sums."""

    n_used: int
    motion: bool
    keep: np.ndarray
    mean_gray: np.ndarray
    med_distance: np.ndarray
    uv: np.ndarray
    rho: np.ndarray
    mixing: np.ndarray


class Measurement(NamedTuple):
    """The measurement of a frame's n blobs (``measure_and_back_project``): ``n_used``,
    ``motion``, ``keep`` (n,), ``uv`` (n, 2) and ``rho`` (n,) (uncorrected) as
    ``persist_and_measure`` gives them, ``ranged`` (r,) int64 the kept blobs with a range,
    and those as ``candidates`` (a ``core.records.Candidates`` of r: corrected ranges,
    sigmas, points, weights, mixing sums)."""

    n_used: int
    motion: bool
    keep: np.ndarray
    uv: np.ndarray
    rho: np.ndarray
    ranged: np.ndarray
    candidates: Candidates
