"""A whole tracking-mode frame as stated: the window search (``reference.tracking``), the
measurement of acquisition (``stages.persistence.reference.measure.measure_and_back_project``) and
§5 on the
known correspondences (``stages.pose.reference.solve.solve_pairs``), chained in the order the
compiled ``track_frame`` chains its stage kernels, with its arguments and returns (the
pipeline's ``implementation="reference"`` tracks with it)."""

from __future__ import annotations

import numpy as np

from tofpose.stages.persistence.reference.measure import measure_and_back_project
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
    correct_perspective,
    mixing_radius_px,
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
    flat, starts, uv, rho, sigma_px, sigma_range, y, weights, uv_obs, e_obs, y_obs, R, t,
    iterations, covariance, chi2, norms, sr, sb, offset, offset sigma); the arrays after
    ``code`` are NaN past the step that set it."""
    n = len(bounds)
    status, bbox, _, cent, starts, flat = search_windows(
        gray, bounds, centres, diameters, threshold, background
    )
    uv, uv_obs = np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    y, e_obs, y_obs = (np.full((n, 3), np.nan) for _ in range(3))
    rho, sp, sr, wts = (np.full(n, np.nan) for _ in range(4))
    fit_out = (
        np.eye(3),
        np.zeros(3),
        0,
        np.full((6, 6), np.nan),
        np.inf,
        np.full(n, np.nan),
        np.full(n, np.nan),
        np.full(n, np.nan),
        0.0,
        offset_prior.sigma_mm,
    )
    n_used, motion = 0, False

    def result(code):
        return (
            code,
            n_used,
            motion,
            cent,
            flat,
            starts,
            uv,
            rho,
            sp,
            sr,
            y,
            wts,
            uv_obs,
            e_obs,
            y_obs,
            *fit_out,
        )

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
    (_, _, uv_obs, e_obs, y_obs, rho, sr, kept, *fit_out) = solve_pairs(
        y,
        wts,
        uv,
        rho,
        sp,
        sr,
        mix,
        np.arange(n),
        np.asarray(cat_idx),
        catalog,
        camera,
        correct_perspective,
        mixing_radius_px,
        0.0,
        fit,
        offset_prior,
    )
    return result(TRACKED if np.all(kept) else OUTLIER)
