"""The records the pixel fit's compiled kernel takes (``kernels.images``):
``typing.NamedTuple``s, which numba compiles as tuples with named fields; each is built
by keyword.

Shapes: K discs; P window pixels; S * S sub-cells per pixel."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class DiscRecord(NamedTuple):
    """The discs fitted: ``centres_mm`` (K, 3), target frame; ``radii_mm`` (K,)."""

    centres_mm: np.ndarray
    radii_mm: np.ndarray


class WindowRays(NamedTuple):
    """The window pixels' rays: ``bearings``, ``dbdu``, ``dbdv`` (P, 3), each pixel's
    centre ray and its derivatives over u and v (per px); ``sample_bearings``,
    ``sample_dbdu``, ``sample_dbdv`` (P, S * S, 3), the same for its sub-cells; disc k
    is evaluated at the pixels ``near_index[near_start[k]:near_start[k + 1]]``
    (``near_start`` (K + 1,))."""

    bearings: np.ndarray
    dbdu: np.ndarray
    dbdv: np.ndarray
    sample_bearings: np.ndarray
    sample_dbdu: np.ndarray
    sample_dbdv: np.ndarray
    near_index: np.ndarray
    near_start: np.ndarray
