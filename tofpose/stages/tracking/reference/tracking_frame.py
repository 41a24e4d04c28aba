"""A whole tracking-mode frame as stated: the window search (``reference.tracking``), the
measurement of acquisition (``stages.persistence.reference.measure.measure_and_back_project``) and
§5 on the
known correspondences (``stages.pose.reference.solve.solve_pairs``), chained in the order the
compiled ``track_frame`` chains its stage kernels, with its arguments and returns (the
pipeline's ``implementation="reference"`` tracks with it)."""

from __future__ import annotations

import numpy as np

from tofpose.core.records import Candidates
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
from tofpose.stages.tracking.reference.tracking import any_shared, search_windows


def track_frame(
    gray,
    distance,
    bounds,
    centres,
    diameters,
    cat_idx,
    threshold,
    background,
    dark,
    history,
    camera,
    catalog,
    correction,
    sigmas,
    fit,
    offset_prior,
    mean_buf,
    med_buf,
):
    """One tracking frame: every window's blob (``search_windows``; ``LOST`` unless each
    is found, ``SHARED`` when two windows hold one component), their persistence,
    centroids, ranges, sigmas and points (``measure_and_back_project``;
    ``NOT_PERSISTENT`` unless every blob is kept, ``NO_RANGE`` unless each has a range),
    then ``solve_pairs`` with blob j matched to catalog reflector ``cat_idx[j]`` and no
    completion (``OUTLIER`` when the fit drops one). Arguments and returns as the
    compiled ``kernels.tracking_frame.track_frame``: (code, n_used, motion, centroids,
    flat, starts, uv, rho, sigma_px, sigma_range, y, weights, the ``SolvedPairs``); the
    arrays after ``code`` are NaN past the step that set it."""
    n = len(bounds)
    status, bbox, _, cent, starts, flat = search_windows(
        gray, bounds, centres, diameters, threshold, background
    )
    uv = np.full((n, 2), np.nan)
    y = np.full((n, 3), np.nan)
    rho, sp, sr, wts = (np.full(n, np.nan) for _ in range(4))
    solved = unsolved(np.asarray(cat_idx), offset_prior.sigma_mm)
    n_used, motion = 0, False

    def result(code):
        return code, n_used, motion, cent, flat, starts, uv, rho, sp, sr, y, wts, solved

    if not all(s == FOUND for s in np.asarray(status).tolist()):
        return result(LOST)
    if any_shared(flat, starts, bbox):
        return result(SHARED)
    n_used, motion, keep, uv, _, ranged, rho, sp, sr, y, wts, mix = measure_and_back_project(
        gray,
        distance,
        flat,
        starts,
        bbox,
        cent,
        np.zeros(n, bool),
        history,
        background,
        dark,
        camera,
        mean_buf,
        med_buf,
        correction,
        sigmas,
    )
    if not np.all(keep):
        return result(NOT_PERSISTENT)
    if len(ranged) < n:
        return result(NO_RANGE)
    candidates = Candidates(
        uv_px=uv, range_mm=rho, y_mm=y, weights=wts, sigma_px=sp, sigma_range_mm=sr, mixing=mix
    )
    solved = solve_pairs(
        candidates, np.arange(n), np.asarray(cat_idx), catalog, camera, fit, 0.0, offset_prior
    )
    rho, sr = solved.observed.rho, solved.observed.sr
    return result(TRACKED if np.all(solved.result.kept) else OUTLIER)


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
