"""A whole tracking-mode frame in one compiled call: window search, persistence,
measurement, sigmas and the §5 fit, chained from the stage kernels so that the frame
pays the Python overhead of one call instead of ~25 (``PosePipeline`` tracks with it;
each stage kernel it chains is tested against ``tofpose.reference``, and its poses
against the reference fit of their own measurements).

The steps and their order: the windows' search, the measurement of acquisition
(``stages.persistence.kernels.measure.measure_and_back_project``: persistence,
centroids, ranges, the range correction, sigmas, Eq. 8) and the compiled §5 of
``PoseSolver.solve`` (``stages.pose.kernels.solve.solve_pairs``; its completion adds
nothing when every blob is matched to its window). The persistence history is read, not
changed: the caller commits the frame to it only when tracking succeeds.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.records import Candidates
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.persistence.kernels.measure import measure_and_back_project
from tofpose.stages.persistence.records import BlobLists, Measurement
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
from tofpose.stages.tracking.records import TrackedFrame


@jit
def track_frame(
    frame, threshold, windows, history, camera, catalog, correction, sigmas, fit, offset_prior
):
    """One tracking frame (module docstring).

    frame : the checked frame (a ``records.FrameRecord``: gray and distance, the last
    acquisition's background and no-return levels); threshold : the last acquisition's
    I_t (float32 counts); windows : the windows (``tracking.records.Windows``,
    ``camera_windows``); history : the persistence history and its settings
    (``records.PersistenceHistory``, ``Persistence.history``); camera, catalog : a
    ``records.CameraRecord`` and ``records.CatalogRecord``; correction : the calibrated
    range correction (``records.RangeCorrectionRecord``); sigmas : the ``uncertainty``
    constants and floors (``records.SigmaConstants``); fit : ``PoseSolver``'s
    ``records.FitSettings``; offset_prior : the common range offset's
    ``pose.records.RangeOffsetPrior``.

    Returns the ``tracking.records.TrackedFrame``: its code, the windows' blobs, what
    persistence combined, their measurement and the fit of the known correspondences;
    what follows the step that set the code is NaN.
    """
    cat_idx = windows.catalog_index
    n = cat_idx.shape[0]
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
        blobs = BlobLists(
            flat=flat, starts=starts, bbox=bbox, centroids=cent, split=np.zeros(n, np.bool_)
        )
        measured = measure_and_back_project(frame, blobs, history, camera, correction, sigmas)
        if not measured.keep.all():
            code = NOT_PERSISTENT
            break
        if measured.ranged.shape[0] < n:
            code = NO_RANGE
            break

        # §5 on the known correspondences (every blob matched: nothing to complete)
        k_idx = np.arange(n)
        solved = solve_pairs(
            measured.candidates, k_idx, cat_idx, catalog, camera, fit, 0.0, offset_prior
        )
        if not solved.result.kept.all():
            code = OUTLIER
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


@jit
def unmeasured(n):
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
        keep=np.zeros(n, np.bool_),
        uv=np.full((n, 2), np.nan),
        rho=np.full(n, np.nan),
        ranged=np.empty(0, np.int64),
        candidates=candidates,
    )


@jit
def unsolved(cat_idx, offset_sigma_mm):
    """A ``SolvedPairs`` of the n windows' reflectors ``cat_idx`` (n,) that no fit has
    seen: NaN observations and fit, nothing kept, no offset (its prior sigma
    ``offset_sigma_mm``)."""
    n = cat_idx.shape[0]
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
        kept=np.zeros(n, np.bool_), fit=fit, offset_mm=0.0, offset_sigma_mm=offset_sigma_mm
    )
    return SolvedPairs(
        k_idx=np.arange(n),
        i_idx=cat_idx,
        uv=np.full((n, 2), np.nan),
        observed=observed,
        result=result,
    )
