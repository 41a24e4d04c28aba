"""Frame pair -> PoseResult: the full measurement pipeline of the paper (§3-§5).

``PosePipeline(camera, catalog, config).process(gray, distance_mm, time_s)`` runs, per
frame: levels and active pixel set (§3.1), candidate blobs (§3.2), ellipse confirmation
and supplement (§3.3), persistence and centroids (§3.4), back-projection (Eqs. 7-9),
deterministic-annealing matching (§4), weighted SVD (§5.1), perspective-bias correction
of the centroids, and refinement (§5.2), and returns a ``PoseResult`` with per-stage
timings. Multi-frame state (persistence history) lives in the pipeline; ``reset()``
clears it.
"""

from __future__ import annotations

import hashlib
import math
import time
from dataclasses import dataclass, field
from typing import Literal

import cv2
import numpy as np

from tofpose.camera import CameraModel
from tofpose.catalog import Catalog
from tofpose.covariance_calibration import CovarianceScale
from tofpose.ellipse import (
    blob_contour,
    ellipse_residual_px,
    ellipses_from_arcs,
    fit_ellipse,
    split_arcs,
)
from tofpose.extraction import (
    Blob,
    CandidateBlobs,
    ExtractionConfig,
    RejectedBlob,
    check_frame,
    find_candidate_blobs,
    frame_levels,
    pixel_lists,
    predicted_diameter_window_px,
)
from tofpose.geometry import facing_euler_deg, quaternion_wxyz_from_rotation
from tofpose.kernels.ellipses import blob_mask
from tofpose.kernels.measure import measure_and_back_project
from tofpose.kernels.pose import covariance_envelope, point_residuals_mm
from tofpose.kernels.range_correction import corrected_ranges
from tofpose.kernels.records import camera_record
from tofpose.kernels.two_centres import SPLIT_OK, two_centre_split
from tofpose.matching import (
    MatchingConfig,
    MatchResult,
    match_by_triplets,
    match_reflectors,
    random_triplets,
)
from tofpose.mixing import mixing_rows, shifted_mixing
from tofpose.pair_fit import fit_pair
from tofpose.persistence import Persistence, PersistenceConfig, PersistenceInfo, blob_arrays
from tofpose.range_calibration import RangeCorrection, correction_kernel_arguments
from tofpose.solve import Measurements, PoseSolver, Rejected, Solution, ThresholdedFrame
from tofpose.tracking import (
    TrackingConfig,
    TrackState,
    find_in_windows,
    predict_windows,
)
from tofpose.tracking_frame import CompiledTracker
from tofpose.uncertainty import (
    UNCALIBRATED_RANGE_SIGMA_MM,
    SigmaFloors,
    kernel_constants,
    measurement_sigmas,
)

Refinement = Literal["ml", "los", "none"]


@dataclass(frozen=True)
class PipelineConfig:
    """All pipeline parameters.

    refinement : "ml" (ours: Gauss-Newton on bearings and ranges, the default), "los"
        (the paper's line-of-sight iteration, Eqs. 51-52), or "none" (SVD only).
    correct_perspective_bias : shift centroids by the predicted offset between the image
        ellipse's centre and the projected disc centre, then re-solve.
    mixed_pixel_radius_px : a matched marker whose disc appears smaller than this
        radius takes its range from the mixing model of its pixels and its surround
        (``kernels.mixed_pixels``) instead of its pixels' median, which the surround
        pulls towards itself when few pixels are covered whole; 0: never (the paper's
        preset). 4 px: from there on most of a disc's pixels are covered whole.
    ellipse_confirmation : run §3.3 (confirm candidate shapes, split merged components).
    verify_pose : refuse a pose that makes the target face away from the camera (beyond
        ``max_view_angle_deg``) or that predicts a well-resolved reflector where the
        frame has no bright pixel (catches congruent-triangle mismatches with 3 markers).
    reject_outliers, outlier_sigma : after the fit, drop the matched reflector whose
        whitened residual (lateral and range, in predicted sigmas) is largest while it
        exceeds ``outlier_sigma`` and more than ``matching.min_matches`` remain, refitting
        each time (ours: a spurious blob or a merged pair next to a marker's position
        passes the matching tolerance but bends the pose by degrees).
    adapt_range_sigma : before the outlier test, estimate from the frame's own residuals
        the range and centroid errors its noise model lacks (``pose.systematic_sigmas``:
        the systematic errors of a real, uncalibrated ToF camera; the centroid errors of
        small markers on a plate that is not black) and add them to every reflector's
        sigmas, in the fit, the outlier test and the covariance; without it, correctly
        detected markers are dropped as outliers one by one, or a biased bearing is
        trusted.
    range_bias_sigma_mm, calibrated_range_bias_sigma_mm : sigma of a range offset common
        to all reflectors that no frame can reveal (the fit absorbs it into the pose): the
        constant, amplitude and temperature-drift errors of a ToF camera without range
        calibration, or what is left of them with one (drift since the calibration; the
        uncalibrated sigma applies where a reflector lies outside the correction's
        ``calibrated_span_mm``, where the model is extrapolated). 15 mm: the middle of
        the 10-20 mm that published uncalibrated CW-ToF cameras err by (zero offset,
        cyclic and amplitude errors; ``docs/simulator.md``), which the robustness
        study's ``systematic`` family draws. Added
        to the reported covariance (``pose.common_range_bias_covariance``), so that the
        1-sigma of an uncalibrated camera does not claim the shot-noise limit.
    max_systematic_range_sigma_mm : cap of that estimate (published uncalibrated ToF
        range errors are 10-20 mm; a larger spread is not a systematic error but a bad
        match, and must stay visible to the outlier test).
    estimate_range_offset : estimate the range offset common to every reflector as a
        seventh parameter of the ML fit, with the prior N(0, range_bias_sigma^2) (the
        calibrated sigma where a range correction covers the ranges), and take its
        posterior mean out of the ranges before the final fit; its posterior sigma
        replaces the prior's in the covariance. The image scale (the bearings) determines
        it when the target is large enough in the image; otherwise the prior keeps it
        near 0. The scale itself is an eighth parameter with its own prior
        (``focal_length_sigma_rel``, ``common_centroid_bias_px``), so an image-scale
        error is not read as a range offset. From 4 reflectors. On by default; a camera
        whose driver states a range-bias sigma of 0 turns it off.
    focal_length_sigma_rel : relative sigma of the focal length's calibration (0.2 %: a
        checkerboard calibration's typical focal-length uncertainty).
    common_centroid_bias_px : sigma of a centroid error common to a frame's markers
        (0.05 px: the largest common-mode error of the matched centroids measured over
        the physics robustness study's families, 0.046 px rms beyond their random
        noise at 8 m with every knob drawn; ``bench/physics.py``'s scale column); over
        the pattern's rms radius in the
        image it is a scale error, estimated with the range offset. Markers of one size
        share it apart from the others (their blobs mix with the surround, the PSF and the
        fall-off alike), so each size's own scale error also enters the reported
        covariance (``solve.PoseSolver.size_scale_covariance``): where the sizes sit on
        different sides of the pattern, the fit reads it as a tilt.
    max_systematic_centroid_sigma_px : cap of the frame's excess centroid sigma, estimated
        beside the range one from the lateral residuals alone (``pose.systematic_sigmas``:
        small or blurred markers against a plate that is not black have centroids off by
        tenths of a pixel that no pixel statistic sees). A matched marker's centroid off
        by more than half a pixel is a blend or a wrong blob, not noise.
    consistency_p : refuse a pose whose chi^2 (with the sigmas the fit used, the excess
        components included) exceeds this quantile of chi^2(3m - 6): a misfit that no
        noise can produce (a one-in-a-million tail), left when a component reached its
        cap or from the minimum number of markers, where no outlier can be singled out
        and no component is estimated. Only with ``refinement="ml"`` (the chi^2 of an
        SVD or LOS pose is not minimised). None: no test. Below the limit, a chi^2 per
        degree of freedom above 1 scales the reported covariance up by it
        (``variance_factor``).
    leave_one_out_covariance : report a covariance no narrower than the spread of the
        poses fitted without one reflector each (from 4 reflectors; ``pose.
        leave_one_out_covariance``): a reflector biased beyond its sigma that alone fixes
        some direction of the pose leaves no residual for chi^2 to see, but moves the
        pose when left out (at 8 m, a marker partly hidden by an arm in front of it, or
        pulled by a blurred neighbour's halo, was 3-6 deg off with 4-5 markers and
        claimed 0.3-1 deg).
    outlier_chi2_per_dof : above this chi^2 per degree of freedom the fit is inconsistent
        and each reflector is also tested against a fit without it (leave-one-out), which
        finds a biased point that a fit of few points has absorbed.
    dark_check_max_matches : the dark-marker check applies only to poses from at most
        this many matched reflectors. Three points always admit a congruent alternative;
        from four on, a wrong assignment either fails the rigid residual check or (a
        mirror image of the nearly planar pattern) makes the target face away, so a dark
        predicted marker is an occluded one.
    centroid_sigma_floor_px, range_sigma_floor_mm : floors of the per-reflector
        measurement sigmas (``tofpose.uncertainty``) used as weights and in the
        covariance.
    """

    extraction: ExtractionConfig = field(default_factory=ExtractionConfig)
    persistence: PersistenceConfig = field(default_factory=PersistenceConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    refinement: Refinement = "ml"
    correct_perspective_bias: bool = True
    mixed_pixel_radius_px: float = 4.0
    ellipse_confirmation: bool = True
    verify_pose: bool = True
    reject_outliers: bool = True
    adapt_range_sigma: bool = True
    max_systematic_range_sigma_mm: float = 25.0
    max_systematic_centroid_sigma_px: float = 0.5
    consistency_p: float | None = 0.999999
    leave_one_out_covariance: bool = True
    estimate_range_offset: bool = True
    range_bias_sigma_mm: float = 15.0
    calibrated_range_bias_sigma_mm: float = 2.0
    focal_length_sigma_rel: float = 0.002
    common_centroid_bias_px: float = 0.05
    outlier_sigma: float = 6.0
    outlier_chi2_per_dof: float = 4.0
    max_view_angle_deg: float = 80.0
    dark_check_max_matches: int = 3
    matcher: Literal["annealing", "ransac"] = "annealing"
    triplet_fallback: bool = True
    ransac_time_budget_ms: float | None = 5.0
    ransac_confidence: float | None = None
    ransac_seed: int = 0
    centroid_sigma_floor_px: float = 0.03
    range_sigma_floor_mm: float = 1.0
    los_tolerance: float = 0.002

    @staticmethod
    def paper() -> PipelineConfig:
        """The paper's literal settings: fixed thresholds, LOS refinement, no bias fix."""
        return PipelineConfig(
            extraction=ExtractionConfig.paper(),
            refinement="los",
            correct_perspective_bias=False,
            mixed_pixel_radius_px=0.0,
            reject_outliers=False,
            adapt_range_sigma=False,
            range_bias_sigma_mm=0.0,
            calibrated_range_bias_sigma_mm=0.0,
            consistency_p=None,
            leave_one_out_covariance=False,
            estimate_range_offset=False,
            focal_length_sigma_rel=0.0,
            common_centroid_bias_px=0.0,
        )


@dataclass
class MatchedReflector:
    """A reflector found in the frame and identified in the catalog."""

    catalog_id: int
    centroid_uv: np.ndarray  # (2,) px, after bias correction
    point_mm: np.ndarray  # (3,) measured position in the camera frame
    residual_mm: float  # |measured - predicted| at the final pose
    distance_mm: float
    area_px: int
    centroid_sigma_px: float = float("nan")  # per image axis (tofpose.uncertainty)
    range_sigma_mm: float = float("nan")


@dataclass
class PoseResult:
    """Output of one frame.

    ok : bool; reason : why not ok (empty when ok).
    R : (3, 3) R_camera_target; t_mm : (3,) target origin in the camera frame.
    euler_deg : (pitch, yaw, roll) in deg of the attitude as people read it: the Euler
        angles (R = Rz(roll) Ry(yaw) Rx(pitch)) of ``R @ diag(1, -1, -1)``, so that a
        target facing the camera reads (0, 0, 0) (docs/architecture.md §3). ``R`` and the
        quaternion stay the raw R_camera_target.
    quaternion_wxyz : (4,).
    matched : list of MatchedReflector; unmatched : list of (u, v, distance_mm) blobs.
    residual_mm : RMS of matched residuals; iterations : refinement iterations.
    covariance : (6, 6) over (rotation vector rad, translation mm), or None.
    timings_ms : per stage; n_candidates; frames_used (persistence); motion detected.
    rejected : components of the active set that are not candidates, with the gate that
        refused each (``tofpose.extraction.REJECT_REASONS``), for display.
    active_threshold_counts : I_t as applied (after the N_max cap): the active pixel set
        A (§3.1.1) is exactly ``gray >= active_threshold_counts``.
    """

    ok: bool
    reason: str = ""
    time_s: float | None = None
    R: np.ndarray | None = None
    t_mm: np.ndarray | None = None
    euler_deg: np.ndarray | None = None
    quaternion_wxyz: np.ndarray | None = None
    matched: list[MatchedReflector] = field(default_factory=list)
    unmatched: list[tuple[float, float, float]] = field(default_factory=list)
    residual_mm: float = float("nan")
    iterations: int = 0
    covariance: np.ndarray | None = None
    timings_ms: dict[str, float] = field(default_factory=dict)
    n_candidates: int = 0
    frames_used: int = 1
    motion: bool = False
    rejected: list[RejectedBlob] = field(default_factory=list)
    active_threshold_counts: float = float("nan")
    mode: Literal["acquisition", "tracking"] = "acquisition"

    @property
    def n_matched(self) -> int:
        return len(self.matched)


def variance_factor(chi2: float, n_reflectors: int) -> float:
    """A-posteriori variance factor max(1, chi^2 / dof), dof = 3 n - 6.

    The covariance (J^T J)^-1 assumes the measurement sigmas are right. When the fit is
    worse than they allow (a biased blob the outlier step could not single out, e.g. one
    of 4), the reported uncertainty grows with it instead of claiming sub-millimetre.
    """
    dof = 3 * n_reflectors - 6
    return max(1.0, chi2 / dof) if dof > 0 and np.isfinite(chi2) else 1.0


class _Timer:
    def __init__(self) -> None:
        self.ms: dict[str, float] = {}
        self._t = time.perf_counter()
        self._start = self._t

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self.ms[name] = self.ms.get(name, 0.0) + (now - self._t) * 1e3
        self._t = now

    def total(self) -> dict[str, float]:
        self.ms["total"] = (time.perf_counter() - self._start) * 1e3
        return self.ms


class PosePipeline:
    """Stateful per-camera pipeline. Not thread-safe: one instance per stream."""

    def __init__(
        self,
        camera: CameraModel,
        catalog: Catalog,
        config: PipelineConfig | None = None,
        range_correction: RangeCorrection | None = None,
        covariance_scale: CovarianceScale | None = None,
    ) -> None:
        """``range_correction``: the camera's calibrated range errors
        (``tofpose.range_calibration``), subtracted from each reflector's range before
        back-projection; None for a camera without one. ``ValueError`` when its
        per-pixel offsets are not of the camera's image size. ``covariance_scale``: the
        camera's covariance calibration (``tofpose.covariance_calibration``), applied to
        the reported covariance at the target's distance; None reports the model's."""
        offsets = None if range_correction is None else range_correction.pixel_offsets_mm
        if offsets is not None and offsets.shape != camera.shape:
            raise ValueError(
                f"the range correction's pixel offsets are {offsets.shape[0]} x "
                f"{offsets.shape[1]} px (rows x columns), the camera's images "
                f"{camera.shape[0]} x {camera.shape[1]}"
            )
        self.camera = camera
        self.range_correction = range_correction
        self.covariance_scale = covariance_scale
        self._correction_kernel_args = correction_kernel_arguments(range_correction)
        self._camera_record = camera_record(camera)
        self.catalog = catalog
        self.config = config or PipelineConfig()
        self._sigma_constants = kernel_constants(
            SigmaFloors(self.config.centroid_sigma_floor_px, self.config.range_sigma_floor_mm)
        )
        self._persistence = Persistence(self.config.persistence)
        self._catalog_xyz = catalog.positions_mm
        self._catalog_d = catalog.diameters_mm
        self._catalog_ids = catalog.ids
        self._rng = np.random.default_rng(self.config.ransac_seed)
        self._solver = PoseSolver(camera, catalog, self.config, range_correction)
        self._track: TrackState | None = None
        self._compiled_tracker = CompiledTracker(
            camera, catalog, self.config, self._solver, self._persistence, range_correction
        )

    def reset(self) -> None:
        """Forget multi-frame history (call when the stream is discontinuous)."""
        self._persistence.reset()
        self._track = None

    def state_digest(self) -> bytes:
        """A digest (16 bytes) of everything a frame leaves for the next ones: the
        persistence history, the tracking state and the RANSAC generator. Two pipelines
        of one configuration whose digests are equal give identical results on the same
        following frames (``tofpose.batch.reprocess`` finds where a chunk started
        mid-recording has caught up with the serial run this way)."""
        h = hashlib.blake2b(digest_size=16)
        self._persistence.update_digest(h)
        tr = self._track
        if tr is None:
            h.update(b"no track")
        else:
            h.update(np.ascontiguousarray(tr.R, float).tobytes())
            h.update(np.ascontiguousarray(tr.t_mm, float).tobytes())
            h.update(np.array([tr.threshold_counts, tr.background_counts, tr.dark_counts,
                               tr.frames_since_acquisition], float).tobytes())  # fmt: skip
        h.update(repr(self._rng.bit_generator.state).encode())
        return h.digest()

    # ------------------------------------------------------------------------------------
    def process(
        self, gray: np.ndarray, distance_mm: np.ndarray, time_s: float | None = None
    ) -> PoseResult:
        """Estimate the pose from one (gray, distance) frame pair.

        Raises ``FrameError`` (a ValueError) for arrays of the wrong shape or dtype;
        every other failure is an ``ok = False`` result with a reason.
        """
        cfg = self.config
        timer = _Timer()
        g, d = check_frame(self.camera, gray, distance_mm)
        track = self._track
        self._track = None  # set again below by a confident pose
        if (
            cfg.tracking.enabled
            and track is not None
            and track.frames_since_acquisition + 1 < cfg.tracking.reacquire_every
        ):
            tracked = self._process_tracking(g, d, time_s, track, timer)
            if tracked is not None:
                return tracked
            timer.lap("tracking fallback")
        stats = frame_levels(g, cfg.extraction)
        timer.lap("levels")

        def fail(reason: str, **kw) -> PoseResult:
            return PoseResult(ok=False, reason=reason, time_s=time_s, timings_ms=timer.total(),
                              **kw)  # fmt: skip

        if stats.saturated_fraction > 0.5:
            self.reset()
            return fail(f"frame saturated: {stats.saturated_fraction:.0%} of pixels at full scale")
        if stats.i_max - stats.background < cfg.extraction.min_contrast_counts:
            self.reset()
            return fail(
                f"no reflector contrast: brightest pixel {stats.i_max:.0f} counts over a "
                f"background of {stats.background:.0f} (all-dark frame?)"
            )
        found, blobs = self._candidates(g, d, stats, timer)
        stats = found.stats  # I_t as applied (after the N_max cap)
        active = ThresholdedFrame(g, stats.raw_threshold)  # A, for the pose check
        # The motion gate compares the cheap moment centroids of find_candidate_blobs;
        # the precise centroids and ranges are measured once, on the combined frames.
        meas, unmatched, n_kept, pinfo = self._measure(blobs, g, d, stats.background,
                                                       stats.dark_level)  # fmt: skip
        timer.lap("measurement")  # §3.4, Eqs. 7-9 and the sigmas
        extra = {
            "frames_used": pinfo.frames_used,
            "motion": pinfo.motion,
            "rejected": list(found.rejected),
            "active_threshold_counts": stats.raw_threshold,
            "n_candidates": n_kept,
        }
        if len(meas.range_mm) < cfg.matching.min_matches:
            return fail(
                f"found {len(meas.range_mm)} candidate reflector(s) with a valid range "
                f"(of {n_kept} blobs), need {cfg.matching.min_matches}"
                + self._size_hint(found.wrong_size),
                unmatched=unmatched + meas.as_unmatched(),
                **extra,
            )
        m = self._match(meas)
        timer.lap("matching")
        if not m.ok:
            return fail(f"matching failed: {m.reason}",
                        unmatched=unmatched + meas.as_unmatched(), **extra)  # fmt: skip
        solved = self._solve_with_fallback(meas, m, active)
        timer.lap("refine")
        if isinstance(solved, Rejected):
            return fail(solved.reason, unmatched=unmatched + meas.as_unmatched(), **extra)
        result = self._pose_result(solved, meas, unmatched, time_s, timer, extra)
        self._track = TrackState(R=result.R, t_mm=result.t_mm,
                                 threshold_counts=stats.raw_threshold,
                                 background_counts=stats.background,
                                 dark_counts=stats.dark_level)  # fmt: skip
        return result

    # -- stages ---------------------------------------------------------------------------
    def _candidates(self, g, d, stats, timer) -> tuple[CandidateBlobs, list[Blob]]:
        """§3.1-§3.3: candidate blobs through the gates, then ellipse confirmation (which
        may split merged components); returns the extraction record and the blobs."""
        cfg = self.config
        found = find_candidate_blobs(g, d, self.camera, self._catalog_d, cfg.extraction, stats)
        timer.lap("blobs")
        blobs = found.accepted
        if cfg.ellipse_confirmation:
            blobs = self._confirm_ellipses(blobs, found.oversize, g, d, found.stats)
        timer.lap("ellipses")
        # ellipse-supplemented blobs have no moment centroid yet: the ellipse's centre
        blobs = [
            b.with_values(centroid_uv=np.array(b.ellipse[0]))
            if b.ellipse is not None and not math.isfinite(b.centroid_uv[0] + b.centroid_uv[1])
            else b
            for b in blobs
        ]
        return found, blobs

    def _measure(self, blobs: list[Blob], g, d, background: float, dark: float):
        """§3.4 and Eqs. 7-8 in one compiled call
        (``kernels.measure.measure_and_back_project``): the blobs combined with the
        consistent persistence history (the frame is then committed to it), their
        centroids (Eq. 19) and ranges (Eq. 20) measured, the calibrated range correction
        applied, and those with a range back-projected (Eq. 8) with their sigmas and the
        weights of Eq. 21. Returns the ``Measurements`` of the kept blobs with a range,
        (u, v, range) of the kept ones without, how many were kept, and what persistence
        combined."""
        cfg, cam, persistence = self.config, self.camera, self._persistence
        cur, flat, starts, bbox = blob_arrays(blobs)
        split = np.array([b.source == "split" for b in blobs], bool)
        pc = cfg.persistence
        (n_used, motion, keep, uv, rho, ranged, rho_r, sp, sr, y, w,
         mix) = measure_and_back_project(
            g, d, flat, starts, bbox, cur, split, *persistence.history(g, d),
            float(pc.motion_tolerance_px), int(pc.c_min), float(background), float(dark),
            self._camera_record, *persistence.scratch(g.shape), self._correction_kernel_args,
            self._sigma_constants,
        )  # fmt: skip
        persistence.commit(cur, flat, g, d, n_used, motion)
        unranged = [(uv[j, 0], uv[j, 1], rho[j]) for j in np.flatnonzero(keep & ~np.isfinite(rho))]
        ranged_blobs = tuple(blobs[j] for j in ranged.tolist())
        uv = uv[ranged]
        fitted = [a for a, b in enumerate(ranged_blobs) if b.fitted_uv is not None]
        if fitted:  # centres from the pair fit replace the halves' moment centroids
            uv, y, w, sr = uv.copy(), y.copy(), w.copy(), sr.copy()
            uv[fitted] = [ranged_blobs[a].fitted_uv for a in fitted]
            # a half's range mixes the neighbour's and the surround's light at the cut:
            # its bearing is used, its range only as a weak constraint
            sr[fitted] = np.maximum(sr[fitted], UNCALIBRATED_RANGE_SIGMA_MM)
            y[fitted] = cam.bearings(uv[fitted]) * rho_r[fitted, None]  # Eq. 8
            w[fitted] = 1.0 / (sr[fitted] ** 2 + (rho_r[fitted] * sp[fitted] / cam.fx) ** 2)
        area = np.array([b.area_px for b in ranged_blobs], np.int64)
        meas = Measurements(ranged_blobs, area, uv, rho_r, y, w, sp, sr, mix)
        n_kept = int(keep.sum())
        return meas, unranged, n_kept, PersistenceInfo(1 + n_used, motion, len(blobs) - n_kept)

    def _back_project(self, blobs, mean_gray, med_distance, background) -> Measurements:
        """Eqs. 7-8 and the per-reflector sigmas of measured blobs (finite ranges), stage
        by stage: the reference of ``_measure``'s compiled back-projection, used by the
        stage-by-stage tracking pass."""
        cfg = self.config
        uv = np.array([b.centroid_uv for b in blobs])
        rho = np.array([b.distance_mm for b in blobs])
        y = self.camera.bearings(uv) * rho[:, None]  # Eq. 8
        sig_px, sig_rng = measurement_sigmas(
            blobs, mean_gray, med_distance, background,
            SigmaFloors(cfg.centroid_sigma_floor_px, cfg.range_sigma_floor_mm),
        )  # fmt: skip
        w = 1.0 / (sig_rng**2 + (rho * sig_px / self.camera.fx) ** 2)  # Eq. 21 weights
        area = np.array([b.area_px for b in blobs], np.int64)
        return Measurements(tuple(blobs), area, uv, rho, y, w, sig_px, sig_rng,
                            mixing_rows(blobs))  # fmt: skip

    def _match(self, meas: Measurements) -> MatchResult:
        """§4: deterministic annealing (with the size term) or, configured, RANSAC."""
        cfg = self.config
        if cfg.matcher == "ransac":
            return self._match_ransac(meas.y_mm, meas.weights)
        diam = np.array([self._apparent_diameter_px(b) for b in meas.blobs])
        return match_reflectors(
            meas.y_mm, self._catalog_xyz, cfg.matching,
            observed_diameter_mm=diam * meas.range_mm / self.camera.fx,
            catalog_diameter_mm=self._catalog_d, weights=meas.weights,
        )  # fmt: skip

    def _solve_with_fallback(self, meas: Measurements, m: MatchResult, active):
        """§5 on the matched pairs; when annealing's assignment gives an implausible pose
        (a mirror image), the exhaustive triplet hypotheses restricted to physically
        possible poses (ours) are solved instead."""
        cfg = self.config
        solved = self._solver.solve(m.pairs, meas, m.alpha_mm, active)
        if not (isinstance(solved, Rejected) and solved.implausible and cfg.triplet_fallback
                and cfg.matcher == "annealing"):  # fmt: skip
            return solved
        tol = cfg.matching.pair_tolerance_mm(m.alpha_mm, meas.weights)
        pairs = match_by_triplets(
            meas.y_mm, self._catalog_xyz, m.alpha_mm, tol,
            self._solver.facing,
            weights=meas.weights, min_matches=cfg.matching.min_matches,
        )  # fmt: skip
        return self._solver.solve(pairs, meas, m.alpha_mm, active) if len(pairs) else solved

    def _process_tracking(self, g, d, time_s, track: TrackState, timer) -> PoseResult | None:
        """Tracking mode (``tofpose.tracking``): reflectors searched only in windows around
        their predicted images, correspondences known; None means "fall back to the full
        acquisition pass", and leaves no trace in the persistence history. The pipeline
        tracks in one compiled call; the stages below, one by one, are its readable
        reference (``tofpose.tracking_frame``), run when there is no compiled tracker."""
        if self._compiled_tracker is not None:
            return self._track_compiled(g, d, time_s, track, timer)
        cfg = self.config
        tc = cfg.tracking
        windows = predict_windows(
            self.camera, self._catalog_xyz, self._catalog_d, track.R, track.t_mm,
            margin_px=tc.margin_px, min_diameter_px=tc.min_diameter_px,
        )  # fmt: skip
        if len(windows) < cfg.matching.min_matches:
            return None
        blobs = find_in_windows(g, windows, track.threshold_counts, track.background_counts)
        if isinstance(blobs, str):
            return None  # a marker lost, moved too far, or two merged: acquire
        timer.lap("windows")
        before = self._persistence.snapshot()

        def give_up() -> None:
            self._persistence.restore(before)

        kept, mean_g, med_d, pinfo = self._persistence.measure(
            blobs, g, d, self.camera, track.background_counts, track.dark_counts
        )
        if len(kept) != len(blobs):
            give_up()
            return None
        if not all(np.isfinite(b.distance_mm) for b in kept):
            give_up()
            return None
        if self.range_correction is not None:
            kept = self._correct_ranges(kept, mean_g)
        timer.lap("centroids")
        meas = self._back_project(kept, mean_g, med_d, track.background_counts)
        pairs = np.column_stack((np.arange(len(kept)), [wd.catalog_index for wd in windows]))
        timer.lap("backproject")
        active = ThresholdedFrame(g, track.threshold_counts)
        solved = self._solver.solve(pairs, meas, cfg.matching.alpha_for(meas.y_mm), active)
        timer.lap("refine")
        if isinstance(solved, Rejected) or len(solved.observations) < len(pairs):
            give_up()  # rejected, or a reflector dropped as an outlier: acquire
            return None
        ml = solved.ml
        if ml.chi2 > cfg.outlier_chi2_per_dof * max(3 * len(pairs) - 6, 1):
            give_up()  # an inconsistent fit: the windows may hold the wrong blobs
            return None
        return self._tracked_result(solved, meas, pinfo, time_s, timer, track)

    def _track_compiled(self, g, d, time_s, track: TrackState, timer) -> PoseResult | None:
        """``_process_tracking`` in one compiled call (``tofpose.tracking_frame``)."""
        tracked = self._compiled_tracker.track(g, d, track)
        timer.lap("tracking")
        if tracked is None:
            return None
        return self._tracked_result(tracked.solution, tracked.measurements, tracked.persistence,
                                    time_s, timer, track)  # fmt: skip

    def _tracked_result(self, solved: Solution, meas: Measurements, info, time_s, timer,
                        track: TrackState) -> PoseResult:  # fmt: skip
        """The ok result of a tracked frame; the track moves on to its pose."""
        extra = {
            "frames_used": info.frames_used,
            "motion": info.motion,
            "rejected": [],
            "active_threshold_counts": track.threshold_counts,
            "n_candidates": len(meas.range_mm),
        }
        result = self._pose_result(solved, meas, [], time_s, timer, extra, mode="tracking")
        self._track = TrackState(
            R=result.R, t_mm=result.t_mm, threshold_counts=track.threshold_counts,
            background_counts=track.background_counts, dark_counts=track.dark_counts,
            frames_since_acquisition=track.frames_since_acquisition + 1,
        )  # fmt: skip
        return result

    def _pose_result(self, solved: Solution, meas: Measurements, unmatched, time_s, timer,
                     extra, mode: str = "acquisition") -> PoseResult:  # fmt: skip
        """The ok result of a ``Solution`` found from ``meas``; ``unmatched`` lists the
        blobs without a range, the unmatched candidates are added."""
        obs, T, ml, iterations = (
            solved.observations,
            solved.T_camera_target,
            solved.ml,
            solved.iterations,
        )
        R, t, x, k_idx, i_idx = T.R, T.t_mm, obs.x_mm, obs.k_idx, obs.i_idx
        uv_m, y_m, rho_m = obs.uv_px, obs.y_mm, obs.range_mm
        area, uv, rho = meas.area_px, meas.uv_px, meas.range_mm
        sig_px = meas.sigma_px
        res, rms = point_residuals_mm(x, y_m, R, t)
        per_reflector = zip(
            self._catalog_ids[i_idx].tolist(), uv_m, y_m, res.tolist(), rho_m.tolist(),
            area[k_idx].tolist(), sig_px[k_idx].tolist(), obs.sigma_range_mm.tolist(),
            strict=True,
        )  # fmt: skip
        matched = [MatchedReflector(*row) for row in per_reflector]
        used = set(k_idx.tolist())
        unmatched += [(uv[k, 0], uv[k, 1], rho[k]) for k in range(len(rho)) if k not in used]
        return PoseResult(
            ok=True,
            reason="",
            time_s=time_s,
            R=R,
            t_mm=t,
            euler_deg=facing_euler_deg(R),
            quaternion_wxyz=quaternion_wxyz_from_rotation(R),
            matched=matched,
            unmatched=unmatched,
            residual_mm=rms,
            iterations=iterations,
            covariance=self._reported_covariance(ml, len(matched), t),
            timings_ms=timer.total(),
            **extra,
            mode=mode,
        )

    def _reported_covariance(self, ml, n_matched: int, t_mm: np.ndarray) -> np.ndarray:
        """(6, 6): the fit's covariance with its a-posteriori variance factor, plus the
        common range bias's and the image scale's (``MLResult.bias_covariance``), widened
        where the leave-one-out poses spread wider (``pose.covariance_envelope``), times
        the camera's calibrated factor at this distance (fitted on what this reports
        without it)."""
        cov = ml.covariance * variance_factor(ml.chi2, n_matched)
        if ml.bias_covariance is not None:
            cov = cov + ml.bias_covariance
        if ml.leave_one_out_covariance is not None:  # pose.covariance_envelope
            cov = covariance_envelope(cov, ml.leave_one_out_covariance)
        if self.covariance_scale is not None:
            cov = cov * self.covariance_scale.factor_at(math.sqrt(float(t_mm @ t_mm)))
        return cov

    def _correct_ranges(self, blobs: list[Blob], gray: np.ndarray) -> list[Blob]:
        """The blobs with the calibrated range error subtracted from their ranges (new
        blobs): the model at the blob's range, evaluated per member pixel (its amplitude,
        the gray level as in the calibration fit; its offset), median
        (``kernels.range_correction.corrected_ranges``)."""
        if not blobs:
            return blobs
        flat, starts = pixel_lists(blobs)
        rho = np.array([b.distance_mm for b in blobs], float)
        out = corrected_ranges(rho, flat, starts, np.asarray(gray, np.float32),
                               *self._correction_kernel_args[1:])  # fmt: skip
        return [b.with_values(distance_mm=float(r), mixing=shifted_mixing(b.mixing, r - r0))
                for b, r, r0 in zip(blobs, out, rho, strict=True)]  # fmt: skip

    def _size_hint(self, wrong_size) -> str:
        """A clause naming bright blobs the catalog's sizes ruled out, or ''."""
        if not wrong_size:
            return ""
        w = max(wrong_size, key=lambda b: b.diameter_px)
        where = f" at {w.distance_mm / 1000:.1f} m" if np.isfinite(w.distance_mm) else ""
        return (
            f"; {len(wrong_size)} bright blob(s) in view do not have a size the catalog "
            f"{self.catalog.name!r} predicts at their range (e.g. {w.diameter_px:.0f} px "
            f"across{where}, expected {w.expected_min_px:.1f}-{w.expected_max_px:.1f} px): "
            "is the right catalog active?"
        )

    def _match_ransac(self, y: np.ndarray, w: np.ndarray) -> MatchResult:
        """Random triplet hypotheses over all blobs, best inlier count, until the time
        budget is spent or (``ransac_confidence``) the standard RANSAC count is reached;
        ``iterations`` of the result = observed triplets tried."""
        cfg = self.config
        stats: dict = {}
        budget = cfg.ransac_time_budget_ms
        alpha = cfg.matching.alpha_for(y)
        tol = cfg.matching.pair_tolerance_mm(alpha, w)
        pairs = match_by_triplets(
            y,
            self._catalog_xyz,
            alpha,
            tol,
            self._solver.facing,
            weights=w,
            min_matches=cfg.matching.min_matches,
            observed_triplets=random_triplets(len(y), self._rng),
            deadline_s=None if budget is None else time.perf_counter() + budget / 1000.0,
            confidence=cfg.ransac_confidence,
            stats=stats,
        )
        matched = set(pairs[:, 0].tolist())
        unmatched = [k for k in range(len(y)) if k not in matched]
        reason = "" if len(pairs) else "no triplet hypothesis with enough inliers"
        tried = stats.get("triplets", 0)
        return MatchResult(pairs, unmatched, np.zeros((len(y), 0)), tried, alpha, reason)

    # ------------------------------------------------------------------------------------
    @staticmethod
    def _apparent_diameter_px(b: Blob) -> float:
        if b.ellipse is not None:
            return float(max(b.ellipse[1]))
        _, _, bw, bh = b.bbox
        return float(max(bw, bh, 2.0 * np.sqrt(b.area_px / np.pi)))

    def _confirm_ellipses(self, blobs, oversize, gray, dist, stats) -> list[Blob]:
        """§3.3: confirm candidate shapes; split oversize components into ellipses.

        A candidate of >= 20 px whose boundary is not an ellipse (RMS > limit) is dropped.
        When there are fewer candidates than catalog reflectors, components rejected as
        too large are searched for elliptical arcs of the predicted size (supplement).
        """
        cfg = self.config.extraction
        h, w = gray.shape
        out = []
        for b in blobs:
            if b.area_px >= 20:
                mask, x0, y0 = _blob_mask(b, w)
                pts = blob_contour(mask, (x0, y0))  # in image coordinates
                if len(pts) >= cfg.ellipse_min_points:
                    e = fit_ellipse(pts)
                    if e is not None:
                        rms_px = ellipse_residual_px(e, pts)
                        if rms_px > cfg.ellipse_max_residual_px:
                            continue
                        b = b.with_values(ellipse=e, ellipse_residual_px=rms_px)
            out.append(b)
        if len(out) >= len(self.catalog) or not oversize:
            return out
        for comp in oversize:
            mask, x0, y0 = _blob_mask(comp, w)
            pts = blob_contour(mask)
            d_lo, d_hi = predicted_diameter_window_px(
                self.camera.fx, comp.distance_mm, self._catalog_d, cfg
            )
            arcs = split_arcs(pts, min_points=cfg.ellipse_min_points)
            found = ellipses_from_arcs(
                arcs, d_min_px=d_lo, d_max_px=d_hi, max_residual_px=cfg.ellipse_max_residual_px
            )
            if not found:
                found_parts = _split_by_threshold(comp, gray, stats.raw_threshold, d_hi,
                                                  cfg.min_area_px)  # fmt: skip
                out += found_parts or _split_in_two(comp, gray, stats.background, d_lo,
                                                    d_hi, cfg.min_area_px)  # fmt: skip
            elif len(found) == 1:
                # one ellipse for a component too large for one reflector: at a few px
                # the outline of a merged pair fits one ellipse of a reflector's size
                # over part of it; a pair's two centres explain all of it
                pair = _split_in_two(comp, gray, stats.background, d_lo, d_hi,
                                     cfg.min_area_px)  # fmt: skip
                if pair:
                    out += pair
                    continue
            for e, _ in found:
                fill = np.zeros_like(mask)
                (cx, cy), (a1, a2), ang = e
                cv2.ellipse(fill, ((cx, cy), (a1, a2), ang), 1, -1)
                inside = (fill > 0) & (mask > 0)
                rows, cols = np.nonzero(inside)
                if len(rows) < cfg.min_area_px:
                    continue
                nb = Blob(
                    pixels=(rows + y0) * w + (cols + x0),
                    area_px=len(rows),
                    bbox=(
                        int(cols.min() + x0),
                        int(rows.min() + y0),
                        int(np.ptp(cols) + 1),
                        int(np.ptp(rows) + 1),
                    ),
                    peak_counts=float(gray[rows + y0, cols + x0].max()),
                    ellipse=((cx + x0, cy + y0), (a1, a2), ang),
                    source="ellipse",
                )
                out.append(nb)
        return out


SPLIT_LEVELS = 12


def _split_by_threshold(
    comp: Blob, gray: np.ndarray, raw_threshold: float, d_max_px: float, min_area_px: int
) -> list[Blob]:
    """Ours (after §3.3): a component too large for one reflector whose outline gives no
    elliptical arcs (small merged markers, e.g. 7 and 8 beyond ~4 m, a few px each) is
    thresholded again at rising levels between I_t and its peak; at the first level where
    it falls apart into two or more parts of at least a tenth of the component each, and
    each no larger than one reflector, those parts' cores are the candidates (their range
    and centroid are measured later as for any blob). Returns [] when no level splits it."""
    h, w = gray.shape
    mask, x0, y0 = _blob_mask(comp, w)
    patch = np.zeros(mask.shape, np.float32)
    rows, cols = np.nonzero(mask)
    patch[rows, cols] = gray[rows + y0, cols + x0]
    peak = float(patch.max())
    for level in np.linspace(raw_threshold, peak, SPLIT_LEVELS + 2)[1:-1]:
        n, labels, st, _ = cv2.connectedComponentsWithStats(
            (patch >= level).astype(np.uint8), connectivity=8
        )
        # parts that are cores of markers, not noise specks on one big disc: each holds
        # at least a tenth of the component
        big = max(min_area_px, 0.1 * comp.area_px)
        parts = [k for k in range(1, n) if st[k, cv2.CC_STAT_AREA] >= big]
        if len(parts) < 2:
            continue
        sizes = [2.0 * np.sqrt(st[k, cv2.CC_STAT_AREA] / np.pi) for k in parts]
        if max(sizes) > d_max_px:
            continue  # still a merged pair in one of the parts: go higher
        out = []
        for k in parts:
            pr, pc = np.nonzero(labels == k)
            out.append(Blob(
                pixels=(pr + y0) * w + (pc + x0),
                area_px=len(pr),
                bbox=(int(pc.min() + x0), int(pr.min() + y0), int(np.ptp(pc) + 1),
                      int(np.ptp(pr) + 1)),
                peak_counts=float(patch[pr, pc].max()),
                distance_mm=comp.distance_mm,
                source="split",
            ))  # fmt: skip
        return out
    return []


#: Lloyd iterations of the two-centre split (they converge in 2-4 on a merged pair)
TWO_CENTRE_ITERATIONS = 8
#: the halves of a merged pair of like reflectors carry light within this ratio (gains
#: of aged or dirty reflectors differ by up to ~30 %, so a pair by up to ~2x)
PAIR_LIGHT_RATIO = 3.0


def _split_in_two(
    comp: Blob, gray: np.ndarray, background: float, d_lo_px: float, d_hi_px: float,
    min_area_px: int,
) -> list[Blob]:  # fmt: skip
    """Ours (after ``_split_by_threshold``): a component the size of two reflectors whose
    light shows no dip between them (two discs a fraction of a pixel apart, integrated
    over the pixel area and blurred by the lens: markers 7 and 8 beyond ~6 m) is cut in
    two by intensity-weighted 2-means (Lloyd's iteration from the ends of its major
    axis), each half's pixels those nearer its centre. Taken only when the component is
    elongated as a pair is (major axis over minor >= 1.5), each half's equivalent
    diameter lies in the window of one reflector (``d_lo_px``..``d_hi_px``) and their
    light is within ``PAIR_LIGHT_RATIO``; returns [] otherwise. Each half's moment
    centroid leans towards the other (it keeps the neighbour's light at the cut), so the
    centres come from a model fit of the pair's pixels (``pair_fit.fit_pair``; no split
    when it fails) and replace the halves' centroids in the measurement
    (``Blob.fitted_uv``); ranges are measured on the halves as any blob's, and the
    centroid sigma keeps the split's term (``uncertainty.SPLIT_CENTROID_PX``). The 2-means
    is compiled (``kernels.two_centres.two_centre_split``)."""
    w = gray.shape[1]
    rows, cols = np.divmod(np.asarray(comp.pixels), w)
    weight = np.maximum(gray[rows, cols].astype(float) - background, 0.0)
    if len(rows) < 2 * min_area_px or weight.sum() <= 0:
        return []
    near, centres, status = two_centre_split(cols.astype(float), rows.astype(float), weight,
                                             TWO_CENTRE_ITERATIONS)  # fmt: skip
    if status != SPLIT_OK:
        return []  # not elongated as two discs side by side are, or one-sided
    light = np.bincount(near, weights=weight, minlength=2)
    if light.max() > PAIR_LIGHT_RATIO * light.min():
        return []  # not two like reflectors (a marker and a glint, or a speck)
    for n_k in np.bincount(near, minlength=2).tolist():  # each half one reflector's size
        if n_k < min_area_px or not d_lo_px <= 2.0 * np.sqrt(n_k / np.pi) <= d_hi_px:
            return []
    fit = fit_pair(gray, comp.pixels, centres, background)
    if fit is None:
        return []  # the halves' moment centroids lean towards each other: not used
    # the fitted disc nearest each half's centroid is that half's centre
    order = np.argmin(((centres[:, None, :] - fit.centres_px[None, :, :]) ** 2).sum(axis=2),
                      axis=1)  # fmt: skip
    if order[0] == order[1]:
        return []
    out = []
    for k in range(2):
        pr, pc = rows[near == k], cols[near == k]
        out.append(Blob(
            pixels=pr * w + pc,
            area_px=len(pr),
            bbox=(int(pc.min()), int(pr.min()), int(np.ptp(pc) + 1), int(np.ptp(pr) + 1)),
            peak_counts=float(gray[pr, pc].max()),
            distance_mm=comp.distance_mm,
            source="split",
            fitted_uv=fit.centres_px[order[k]],
        ))  # fmt: skip
    return out


def _blob_mask(b: Blob, width: int) -> tuple[np.ndarray, int, int]:
    """Binary mask of a blob in its bounding box padded by 1 px, and the box origin."""
    x, y, bw, bh = b.bbox
    return blob_mask(b.pixels, x, y, bw, bh, width), x - 1, y - 1
