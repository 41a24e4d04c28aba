"""The records of the triplet search (``kernels.triplets.triplet_search`` and its
reference statement), built by keyword in ``matching.match_by_triplets`` and passed whole.
``typing.NamedTuple``s: numba compiles them as tuples with named fields."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class TripletProblem(NamedTuple):
    """What the search matches: ``observed`` (n, 3) mm, camera frame; ``catalog`` (e, 3)
    mm, target frame; ``weights`` (n,) the observed points' weights; ``tol_mm`` (n,) their
    inlier tolerances; ``alpha_mm`` the side-length tolerance; ``cat_tri`` (P, 3) int64
    and ``cat_sides`` (P, 3) mm the catalog's ordered triplets and their sides
    (``catalog_triplets``)."""

    observed: np.ndarray
    catalog: np.ndarray
    weights: np.ndarray
    tol_mm: np.ndarray
    alpha_mm: float
    cat_tri: np.ndarray
    cat_sides: np.ndarray


class TripletRule(NamedTuple):
    """How a hypothesis is judged and when the search stops: with ``constrain``, only
    poses with ``facing_cosine(R, t, centroid) >= cos_min`` (``centroid`` (3,) the
    catalog's); at least ``min_matches`` inliers; with ``use_confidence``, stop once the
    triplets tried reach ``trials_needed`` for the best inlier count at ``confidence``."""

    constrain: bool
    centroid: np.ndarray
    cos_min: float
    min_matches: int
    use_confidence: bool
    confidence: float


class TripletBest(NamedTuple):
    """The search so far: ``pairs`` (k, 2) int64 (observed, catalog) of the best
    hypothesis, its ``n_inliers`` and weighted squared residual ``cost``, and the
    observed triplets ``tried``."""

    pairs: np.ndarray
    n_inliers: int
    cost: float
    tried: int
