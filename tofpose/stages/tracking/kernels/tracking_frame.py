"""A whole tracking-mode frame in one compiled call: window search, persistence,
measurement, sigmas and the §5 fit, chained from the stage kernels so that the frame
pays the Python overhead of one call instead of ~25 (``PosePipeline`` tracks with it;
each stage kernel it chains is tested against ``tofpose.reference``, and its poses
against the reference fit of their own measurements).

The steps and their order: the windows' search, the measurement of acquisition
(``stages.persistence.kernels.measure.measure_and_back_project``: persistence, centroids, ranges,
the
range correction, sigmas, Eq. 8) and the compiled §5 of ``PoseSolver.solve``
(``stages.pose.kernels.solve.solve_pairs``; its completion adds nothing when every blob is matched
to its window). The persistence history is read, not changed: the
caller commits the frame to it only when tracking succeeds.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.records import Candidates
from tofpose.stages.persistence.kernels.measure import measure_and_back_project
from tofpose.stages.pose.kernels.solve import solve_pairs
from tofpose.stages.pose.records import OutlierFit, PoseFit, Reflectors, SolvedPairs
from tofpose.stages.tracking.constants import (
    FOUND,
    LOST,
    NO_RANGE,
    NOT_PERSISTENT,
    OUTLIER,
    SHARED,
    TRACKED,
)
from tofpose.stages.tracking.kernels.tracking import any_shared, search_windows


@jit
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
    """One tracking frame (module docstring).

    gray, distance : (H, W) float32 checked frame; bounds (n, 4), centres (n, 2),
    diameters (n,), cat_idx (n,) : the windows (``tracking.predict_windows``);
    threshold, background, dark : the last acquisition's I_t, background and no-return
    level, counts;
    history : the persistence history and its settings (``records.PersistenceHistory``,
    ``Persistence.history``); camera, catalog : a
    ``records.CameraRecord`` and ``records.CatalogRecord``; correction : the calibrated range
    correction (``records.RangeCorrectionRecord``); sigmas : the ``uncertainty``
    constants and floors (``records.SigmaConstants``); fit : ``PoseSolver``'s
    ``records.FitSettings``; offset_prior : a ``pose.RangeOffsetPrior``; mean_buf,
    med_buf : the persistence's scratch frames (``Persistence.scratch``).

    Returns (code, n_used, motion, centroids (n, 2) moment centroids, flat, starts,
    uv (n, 2) measured centroids, rho (n,) ranges (the mixing model's where it applied),
    sigma_px (n,), sigma_range (n,), y (n, 3) back-projected points (Eq. 8), weights (n,)
    (Eq. 21), and ``solve_pairs``' ``SolvedPairs``); the arrays after ``code`` are only
    meaningful up to the step that set it.
    """
    n = bounds.shape[0]
    status, bbox, peak, cent, starts, flat = search_windows(
        gray, bounds, centres, diameters, threshold, background
    )
    uv = np.full((n, 2), np.nan)
    rho = np.full(n, np.nan)
    sp = np.full(n, np.nan)
    sr = np.full(n, np.nan)
    y = np.full((n, 3), np.nan)
    wts = np.full(n, np.nan)
    solved = unsolved(cat_idx, offset_prior.sigma_mm)
    n_used, motion = 0, False
    code = TRACKED
    for _ in range(1):  # one pass; ``break`` ends the frame with ``code``
        for j in range(n):
            if status[j] != FOUND:
                code = LOST
        if code == LOST:
            break
        if any_shared(flat, starts, bbox):
            code = SHARED
            break

        # §3.4 (persistence over the consistent history, then Eqs. 19-20), the range
        # correction, Eqs. 7-8 with the sigmas and Eq. 21's weights
        n_used, motion, keep, uv, _, ranged, rho, sp, sr, y, wts, mix = measure_and_back_project(
            gray,
            distance,
            flat,
            starts,
            bbox,
            cent,
            np.zeros(n, np.bool_),
            history,
            background,
            dark,
            camera,
            mean_buf,
            med_buf,
            correction,
            sigmas,
        )
        if not keep.all():
            code = NOT_PERSISTENT
            break
        if ranged.shape[0] < n:
            code = NO_RANGE
            break

        # §5 on the known correspondences (every blob matched: nothing to complete)
        candidates = Candidates(
            uv_px=uv, range_mm=rho, y_mm=y, weights=wts, sigma_px=sp, sigma_range_mm=sr, mixing=mix
        )
        solved = solve_pairs(
            candidates, np.arange(n), cat_idx, catalog, camera, fit, 0.0, offset_prior
        )
        rho, sr = solved.observed.rho, solved.observed.sr  # every blob is matched, in order
        if not solved.result.kept.all():
            code = OUTLIER
    return code, n_used, motion, cent, flat, starts, uv, rho, sp, sr, y, wts, solved


@jit
def unsolved(cat_idx, offset_sigma_mm):
    """A ``SolvedPairs`` of the n windows' reflectors ``cat_idx`` (n,) that no fit has
    seen: NaN observations and fit, nothing kept, no offset (its prior sigma
    ``offset_sigma_mm``)."""
    n = cat_idx.shape[0]
    nothing = np.full(n, np.nan)
    fit = PoseFit(
        R=np.eye(3),
        t=np.zeros(3),
        iterations=0,
        covariance=np.full((6, 6), np.nan),
        chi2=np.inf,
        norms=nothing.copy(),
        sr=nothing.copy(),
        sb=nothing.copy(),
    )
    observed = Reflectors(
        x=np.full((n, 3), np.nan),
        e=np.full((n, 3), np.nan),
        rho=nothing.copy(),
        sr=nothing.copy(),
        sb=nothing.copy(),
    )
    result = OutlierFit(
        kept=np.zeros(n, np.bool_), fit=fit, offset_mm=0.0, offset_sigma_mm=offset_sigma_mm
    )
    return SolvedPairs(
        k_idx=np.arange(n),
        i_idx=cat_idx,
        uv=np.full((n, 2), np.nan),
        observed=observed,
        result=result,
    )
