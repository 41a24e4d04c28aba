"""A whole tracking-mode frame as stated: the window search (``reference.tracking``), the
measurement of acquisition (``stages.persistence.reference.measure.measure_and_back_project``)
and §5 on the known correspondences (``stages.pose.reference.solve.solve_pairs``), chained
in the order the compiled ``track_frame`` chains its stage kernels, with its arguments and
returns (the pipeline's ``implementation="reference"`` tracks with it)."""

from __future__ import annotations

import numpy as np

from tofpose.core.records import Candidates
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.persistence.records import BlobLists, Measurement
from tofpose.stages.persistence.reference.measure import measure_and_back_project
from tofpose.stages.pose.records import OutlierFit, PoseFit, Reflectors, SolvedPairs
from tofpose.stages.pose.reference.solve import solve_pairs
from tofpose.stages.tracking.constants import (
    FOUND,
    LOST,
    NO_RANGE,
    NOT_PERSISTENT,
    OUTLIER,
    SHARED,
    TRACKED,
)
from tofpose.stages.tracking.records import TrackedFrame
from tofpose.stages.tracking.reference.tracking import any_shared, search_windows


def track_frame(
    frame, threshold, windows, history, camera, catalog, correction, sigmas, fit, offset_prior
):
    """One tracking frame: every window's blob (``search_windows``; ``LOST`` unless each
    is found, ``SHARED`` when two windows hold one component), their persistence,
    centroids, ranges, sigmas and points (``measure_and_back_project``;
    ``NOT_PERSISTENT`` unless every blob is kept, ``NO_RANGE`` unless each has a range),
    then ``solve_pairs`` with blob j matched to catalog reflector
    ``windows.catalog_index[j]`` and no completion (``OUTLIER`` when the fit drops one).
    Arguments and returns (a ``TrackedFrame``) as the compiled
    ``kernels.tracking_frame.track_frame``'s; what follows the step that set the code is
    NaN."""
    cat_idx = np.asarray(windows.catalog_index)
    n = len(cat_idx)
    status, bbox, _, cent, starts, flat = search_windows(
        frame.gray,
        windows.bounds,
        windows.centres,
        windows.diameters_px,
        threshold,
        frame.background,
    )
    measured = unmeasured(n)
    solved = unsolved(cat_idx, offset_prior.sigma_mm)

    def result(code):
        return TrackedFrame(
            code=code,
            centroids=cent,
            flat=flat,
            starts=starts,
            n_used=measured.n_used,
            motion=measured.motion,
            candidates=measured.candidates,
            solved=solved,
        )

    if not all(s == FOUND for s in np.asarray(status).tolist()):
        return result(LOST)
    if any_shared(flat, starts, bbox):
        return result(SHARED)
    blobs = BlobLists(flat=flat, starts=starts, bbox=bbox, centroids=cent, split=np.zeros(n, bool))
    measured = measure_and_back_project(frame, blobs, history, camera, correction, sigmas)
    if not np.all(measured.keep):
        return result(NOT_PERSISTENT)
    if len(measured.ranged) < n:
        return result(NO_RANGE)
    solved = solve_pairs(
        measured.candidates, np.arange(n), cat_idx, catalog, camera, fit, 0.0, offset_prior
    )
    return result(TRACKED if np.all(solved.result.kept) else OUTLIER)


def unmeasured(n) -> Measurement:
    """The ``Measurement`` of n blobs that no measurement has seen: nothing combined or
    kept, NaN everywhere, no blob ranged."""
    candidates = Candidates(
        uv_px=np.full((n, 2), np.nan),
        range_mm=np.full(n, np.nan),
        y_mm=np.full((n, 3), np.nan),
        weights=np.full(n, np.nan),
        sigma_px=np.full(n, np.nan),
        sigma_range_mm=np.full(n, np.nan),
        mixing=np.full((n, MIX_FIELDS), np.nan),
    )
    return Measurement(
        n_used=0,
        motion=False,
        keep=np.zeros(n, bool),
        uv=np.full((n, 2), np.nan),
        rho=np.full(n, np.nan),
        ranged=np.empty(0, np.int64),
        candidates=candidates,
    )


def unsolved(cat_idx, offset_sigma_mm) -> SolvedPairs:
    """A ``SolvedPairs`` of the n windows' reflectors ``cat_idx`` (n,) that no fit has
    seen: NaN observations and fit, nothing kept, no offset (its prior sigma)."""
    n = len(cat_idx)
    fit = PoseFit(
        R=np.eye(3),
        t=np.zeros(3),
        iterations=0,
        covariance=np.full((6, 6), np.nan),
        chi2=np.inf,
        norms=np.full(n, np.nan),
        sr=np.full(n, np.nan),
        sb=np.full(n, np.nan),
    )
    observed = Reflectors(
        x=np.full((n, 3), np.nan),
        e=np.full((n, 3), np.nan),
        rho=np.full(n, np.nan),
        sr=np.full(n, np.nan),
        sb=np.full(n, np.nan),
    )
    result = OutlierFit(
        kept=np.zeros(n, bool), fit=fit, offset_mm=0.0, offset_sigma_mm=offset_sigma_mm
    )
    return SolvedPairs(
        k_idx=np.arange(n),
        i_idx=cat_idx,
        uv=np.full((n, 2), np.nan),
        observed=observed,
        result=result,
    )
