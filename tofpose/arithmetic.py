"""The arithmetic the pipeline's orchestration calls, as one record per implementation.

``Arithmetic`` holds, as fields, every function of arithmetic that the stages
(``pipeline``, ``solve``, ``matching``, ``ellipse``, ``pair_fit``, ``tracking``,
``tracking_frame``) call; ``COMPILED`` holds the compiled kernels (``tofpose.kernels``),
``REFERENCE`` their plain NumPy/SciPy statements (``tofpose.reference``).
``PosePipeline(..., implementation="reference")`` runs the whole chain on ``REFERENCE``:
the reference is then both the kernels' test oracle and an A/B baseline of the pipeline.

Each field has one calling convention, the kernel's; where a reference function has
another form, a small adapter here gives it the kernel's (the reference package stays
free of the pipeline's records). The two extraction fields take and return
``tofpose.extraction``'s records: their compiled values are ``extraction.frame_levels``
and ``extraction.find_candidate_blobs`` themselves (extraction sits below this module,
so it cannot take an ``Arithmetic`` itself without an import cycle).

Not covered (the reference path still runs compiled code there): the frame check's
float32 conversion (``extraction.check_frame``: ``kernels.levels.checked_frame``,
``clean_distance``), the persistence history's pixel masks (``persistence.Persistence.
commit``: ``kernels.persistence.pixel_mask``) and the ``CameraModel`` records built once
at construction (``camera_record``'s pixel bearings).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from tofpose.camera import CameraModel
from tofpose.config import ExtractionConfig
from tofpose.extraction import (
    Blob,
    CandidateBlobs,
    FrameStats,
    RejectedBlob,
    WrongSizeBlob,
    find_candidate_blobs,
    frame_levels,
)
from tofpose.kernels import (
    annealing,
    ellipses,
    measure,
    pair_fit,
    pose,
    residual_check,
    solve,
    tracking,
    tracking_frame,
    triplets,
    two_centres,
    verify,
)
from tofpose.reference import camera as ref_camera
from tofpose.reference import ellipses as ref_ellipses
from tofpose.reference import extraction as ref_extraction
from tofpose.reference import matching as ref_matching
from tofpose.reference import measure as ref_measure
from tofpose.reference import pair_fit as ref_pair_fit
from tofpose.reference import pose as ref_pose
from tofpose.reference import solve as ref_solve
from tofpose.reference import tracking as ref_tracking
from tofpose.reference import tracking_frame as ref_tracking_frame
from tofpose.reference import triplets as ref_triplets
from tofpose.reference import two_centres as ref_two_centres
from tofpose.reference import verify as ref_verify

#: the names ``PosePipeline(implementation=...)`` accepts
IMPLEMENTATIONS = ("compiled", "reference")


@dataclass(frozen=True)
class Arithmetic:
    """The functions of arithmetic the orchestration calls, each with its kernel's
    arguments and returns (``tofpose.kernels.<module>.<name>``), except where a field's
    comment says otherwise."""

    name: str
    # §3.1-§3.2 (extraction's records: ``FrameStats``, ``CandidateBlobs``)
    frame_levels: Callable[[np.ndarray, ExtractionConfig], FrameStats]
    find_candidate_blobs: Callable[..., CandidateBlobs]
    # §3.3: ellipse confirmation, and the split of a merged pair
    blob_mask: Callable
    ellipse_rms_px: Callable
    arc_points: Callable
    two_centre_split: Callable
    fit_pair_lm: Callable
    # §3.4, Eqs. 7-9; ``bearings(camera, uv)`` (Eq. 9) as ``CameraModel.bearings``
    measure_and_back_project: Callable
    bearings: Callable[[CameraModel, np.ndarray], np.ndarray]
    # §4
    pair_potentials: Callable
    size_mismatch: Callable
    anneal_assignment: Callable
    one_to_one: Callable  # A (g, e + 1) -> (pairs (m, 2) int64, unmatched list)
    prune_pairs: Callable
    catalog_triplets: Callable
    triplet_search: Callable
    trials_needed: Callable
    # §5 and what the pipeline reports
    solve_pairs: Callable
    pose_check: Callable
    facing_cosine: Callable
    absolute_orientation: Callable
    range_bias_covariance: Callable
    class_scale_covariance: Callable
    leave_one_out_spread: Callable
    covariance_envelope: Callable
    point_residuals_mm: Callable
    # tracking mode
    camera_windows: Callable
    search_windows: Callable
    any_shared: Callable
    track_frame: Callable


# -- the compiled path's own Python ---------------------------------------------------------


def _compiled_one_to_one(A: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """``matching.one_to_one``: the cost matrix and the reading of the assignment
    compiled (``kernels.annealing.assignment_costs``, ``assigned_pairs``), the
    assignment SciPy's."""
    cost = annealing.assignment_costs(-np.log(np.maximum(A, 1e-300)))  # finite: A > 0
    rows, cols = linear_sum_assignment(cost)
    pairs, unmatched = annealing.assigned_pairs(rows.astype(np.int64), cols.astype(np.int64),
                                                cost, A.shape[1] - 1)  # fmt: skip
    return pairs, unmatched.tolist()


# -- adapters: the reference's forms in the kernels' convention -----------------------------


def _reference_frame_levels(gray: np.ndarray, config: ExtractionConfig) -> FrameStats:
    """``reference.extraction.frame_levels`` as an ``extraction.FrameStats``."""
    v = ref_extraction.frame_levels(gray, config)
    return FrameStats(
        background=v.background, noise_sigma=v.noise_sigma, i_max=v.i_max,
        raw_threshold=v.raw_threshold, peak_threshold=v.peak_threshold, n_active=v.n_active,
        saturated_fraction=v.saturated_fraction, dark_level=v.dark_level,
    )  # fmt: skip


def _reference_find_candidate_blobs(
    gray: np.ndarray, distance_mm: np.ndarray, camera: CameraModel, diameters_mm: np.ndarray,
    config: ExtractionConfig, stats: FrameStats,
) -> CandidateBlobs:  # fmt: skip
    """``reference.extraction.find_candidates`` as ``extraction.find_candidate_blobs``
    returns it (``Blob`` records, the active mask as uint8)."""
    levels = ref_extraction.FrameLevels(
        stats.background, stats.noise_sigma, stats.i_max, stats.raw_threshold,
        stats.peak_threshold, stats.saturated_fraction, stats.dark_level, stats.n_active,
    )  # fmt: skip
    found = ref_extraction.find_candidates(gray, distance_mm, levels, fx=float(camera.fx),
                                           diameters_mm=np.asarray(diameters_mm, float),
                                           config=config)  # fmt: skip
    # the reference's records carry Blob's fields under Blob's names
    accepted = [Blob(**b._asdict()) for b in found.accepted]
    oversize = [Blob(**b._asdict()) for b in found.oversize]
    v = found.levels
    applied = FrameStats(
        background=v.background, noise_sigma=v.noise_sigma, i_max=v.i_max,
        raw_threshold=v.raw_threshold, peak_threshold=v.peak_threshold, n_active=v.n_active,
        saturated_fraction=v.saturated_fraction, dark_level=v.dark_level,
        psf_sigma_px=float(found.psf_sigma_px),
    )  # fmt: skip
    return CandidateBlobs(
        accepted, oversize, found.active_mask.astype(np.uint8),
        tuple(WrongSizeBlob(*(float(x) for x in w)) for w in found.wrong_size),
        tuple(RejectedBlob(float(r.u_px), float(r.v_px), float(r.diameter_px), r.reason)
              for r in found.rejected),
        applied,
    )  # fmt: skip


def _reference_bearings(camera: CameraModel, uv: np.ndarray) -> np.ndarray:
    """Eq. 9 (``reference.camera.bearings``) for ``CameraModel.bearings``' arguments."""
    return ref_camera.bearings(np.asarray(uv, float).reshape(-1, 2), camera.K, camera.dist_array)


#: the status the compiled split returns for a refused split (the reference says None)
_SPLIT_REFUSED = two_centres.SPLIT_ROUND


def _reference_two_centre_split(cols, rows, weight, iterations):
    """``reference.two_centres.two_centre_split`` with the kernel's status: ``SPLIT_OK``,
    or a refusal (``SPLIT_ROUND``; the reference does not say which) with empty halves."""
    split = ref_two_centres.two_centre_split(cols, rows, weight, iterations)
    if split is None:
        return np.zeros(len(cols), np.int64), np.full((2, 2), np.nan), _SPLIT_REFUSED
    near, centres = split
    return np.asarray(near, np.int64), centres, two_centres.SPLIT_OK


def _reference_anneal(Pm, unary, psi, psi_end, growth):
    """``reference.matching.anneal`` on the kernel's flattened P (g e, g e)."""
    g, e = unary.shape
    return ref_matching.anneal(np.reshape(Pm, (g, e, g, e)), unary, psi, psi_end, growth)


def _reference_prune_pairs(observed, catalog, pairs, weights, tol, min_matches):
    """``reference.matching.rigid_residual_check`` with the rejected blobs as an int64
    array, as ``kernels.residual_check.prune_pairs`` returns them."""
    kept, rejected, ok = ref_matching.rigid_residual_check(observed, catalog, pairs, weights,
                                                           tol, min_matches)  # fmt: skip
    return kept, np.asarray(rejected, np.int64), ok


#: (field, compiled, reference): the two implementations of each field side by side
_FUNCTIONS = (
    ("frame_levels", frame_levels, _reference_frame_levels),
    ("find_candidate_blobs", find_candidate_blobs, _reference_find_candidate_blobs),
    ("blob_mask", ellipses.blob_mask, ref_ellipses.blob_mask),
    ("ellipse_rms_px", ellipses.ellipse_rms_px, ref_ellipses.ellipse_rms_px),
    ("arc_points", ellipses.arc_points, ref_ellipses.arc_points),
    ("two_centre_split", two_centres.two_centre_split, _reference_two_centre_split),
    ("fit_pair_lm", pair_fit.fit_pair_lm, ref_pair_fit.fit_pair_lm),
    (
        "measure_and_back_project",
        measure.measure_and_back_project,
        ref_measure.measure_and_back_project,
    ),
    ("bearings", CameraModel.bearings, _reference_bearings),
    ("pair_potentials", annealing.pair_potentials, ref_matching.pair_potentials),
    ("size_mismatch", annealing.size_mismatch, ref_matching.size_mismatch),
    ("anneal_assignment", annealing.anneal_assignment, _reference_anneal),
    ("one_to_one", _compiled_one_to_one, ref_matching.one_to_one),
    ("prune_pairs", residual_check.prune_pairs, _reference_prune_pairs),
    ("catalog_triplets", triplets.catalog_triplets, ref_triplets.catalog_triplets),
    ("triplet_search", triplets.triplet_search, ref_triplets.triplet_search),
    ("trials_needed", triplets.trials_needed, ref_triplets.trials_needed),
    ("solve_pairs", solve.solve_pairs, ref_solve.solve_pairs),
    ("pose_check", verify.pose_check, ref_verify.pose_check),
    ("facing_cosine", pose.facing_cosine, ref_pose.facing_cosine),
    ("absolute_orientation", pose.absolute_orientation, ref_pose.absolute_orientation),
    ("range_bias_covariance", pose.range_bias_covariance, ref_pose.range_bias_covariance),
    ("class_scale_covariance", pose.class_scale_covariance, ref_pose.class_scale_covariance),
    ("leave_one_out_spread", pose.leave_one_out_spread, ref_pose.leave_one_out_spread),
    ("covariance_envelope", pose.covariance_envelope, ref_pose.covariance_envelope),
    ("point_residuals_mm", pose.point_residuals_mm, ref_pose.point_residuals_mm),
    ("camera_windows", tracking.camera_windows, ref_tracking.camera_windows),
    ("search_windows", tracking.search_windows, ref_tracking.search_windows),
    ("any_shared", tracking.any_shared, ref_tracking.any_shared),
    ("track_frame", tracking_frame.track_frame, ref_tracking_frame.track_frame),
)

COMPILED = Arithmetic("compiled", **{field: c for field, c, _ in _FUNCTIONS})
REFERENCE = Arithmetic("reference", **{field: r for field, _, r in _FUNCTIONS})


def arithmetic_for(implementation: str) -> Arithmetic:
    """``COMPILED`` for "compiled", ``REFERENCE`` for "reference"; ``ValueError`` naming
    the accepted values otherwise."""
    for a in (COMPILED, REFERENCE):
        if implementation == a.name:
            return a
    raise ValueError(
        f"unknown implementation {implementation!r}: expected one of "
        + ", ".join(repr(n) for n in IMPLEMENTATIONS)
    )
