"""The records the extraction stage's mixed-pixel and centroid arithmetic passes between
its steps (``kernels.mixed_pixels``, ``kernels.centroids`` and their reference statement
``reference.mixed_pixels``, which return the same records). ``typing.NamedTuple``s:
numba compiles them as tuples with named fields."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class OwnerMap(NamedTuple):
    """Which blob owns each pixel where a neighbour's pixels must be left out
    (``owner_map``): ``owner`` (h', w') int32 (blob index, -1 none) over the part of the
    image whose top-left pixel is (``x0``, ``y0``); ``used`` False when no blob's
    surround reaches another's box (nothing to leave out; ``owner`` is then a (1, 1)
    map of -1)."""

    owner: np.ndarray
    x0: int
    y0: int
    used: bool


class Surrounds(NamedTuple):
    """The surface around each of n blobs (``blob_surrounds``): ``gray`` (n,) counts
    (NaN with no ring pixel), ``distance_mm`` (n,) (NaN with fewer than 3 ranged ring
    pixels) and ``crowded`` (n,) bool, another blob's pixels in the ring."""

    gray: np.ndarray
    distance_mm: np.ndarray
    crowded: np.ndarray
