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
from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np
from scipy.spatial.transform import Rotation

from tofpose.arithmetic import Arithmetic, arithmetic_for
from tofpose.calibration.covariance import CovarianceScale
from tofpose.calibration.range import RangeCorrection, correction_kernel_arguments
from tofpose.config import PipelineConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import facing_euler_deg, quaternion_wxyz_from_rotation
from tofpose.core.records import FrameRecord, camera_record
from tofpose.stages.ellipses.confirmation import confirm_ellipses
from tofpose.stages.extraction.extraction import (
    Blob,
    CandidateBlobs,
    RejectedBlob,
    check_frame,
)
from tofpose.stages.extraction.saturation import blobs_at_full_scale
from tofpose.stages.extraction.surface import thresholds_above_surface
from tofpose.stages.extraction.uncertainty import (
    UNCALIBRATED_RANGE_SIGMA_MM,
    SigmaFloors,
    kernel_constants,
)
from tofpose.stages.extraction.wrap import (
    MAX_READINGS,
    WrapSuggestion,
    max_reading_mm,
    readings_beyond,
    suggested_ranges_mm,
    unwrap_about,
)
from tofpose.stages.matching.matching import (
    MatchResult,
    match_by_triplets,
    match_reflectors,
    random_triplets,
)
from tofpose.stages.persistence.persistence import Persistence, PersistenceInfo, blob_lists
from tofpose.stages.pixelfit.fit import PixelFitResult, PixelNoise, fit_pose_to_pixels
from tofpose.stages.pose.constants import (
    MIN_VARIANCE_FACTOR,
    NARROWING_CONFIDENCE,
    NARROWING_MIN_REFLECTORS,
)
from tofpose.stages.pose.records import NO_RANGE_OFFSET, RangeOffset
from tofpose.stages.pose.solve import (
    Measurements,
    PoseSolver,
    Rejected,
    Solution,
    ThresholdedFrame,
    chi2_limit,
)
from tofpose.stages.tracking.tracking import (
    TrackState,
)
from tofpose.stages.tracking.tracking_frame import CompiledTracker, Tracked


@dataclass
class MatchedReflector:
    """A reflector found in the frame and identified in the catalog."""

    catalog_id: int
    centroid_uv: np.ndarray  # (2,) px, after bias correction
    point_mm: np.ndarray  # (3,) measured position in the camera frame
    residual_mm: float  # |measured - predicted| at the final pose
    distance_mm: float
    area_px: int
    centroid_sigma_px: float = float("nan")  # per image axis (extraction.uncertainty)
    range_sigma_mm: float = float("nan")
    #: a pixel of its blob reads at or above the camera's full scale in this frame's gray
    #: image (``CameraModel.full_scale_counts``): clipped, without a distance there
    saturated: bool = False


@dataclass(frozen=True)
class FrameDiagnostics:
    """What extraction and persistence made of a frame (``PoseResult``'s properties of
    the same names read it).

    n_candidates : blobs persistence kept; frames_used : frames it combined (1: this
    one alone); motion : it cut its history; rejected : components of the active set
    that are not candidates, with the gate that refused each
    (``tofpose.stages.extraction.extraction.REJECT_REASONS``); active_threshold_counts : I_t as
    applied
    (after the N_max cap): the active pixel set A (§3.1.1) is exactly ``gray >=
    active_threshold_counts``; surface_level_counts : the lit surface's gray that I_t
    was raised above (``stages.extraction.surface``), NaN where none was lit.
    """

    n_candidates: int = 0
    frames_used: int = 1
    motion: bool = False
    rejected: tuple[RejectedBlob, ...] = ()
    active_threshold_counts: float = float("nan")
    surface_level_counts: float = float("nan")


#: the diagnostics of a frame refused before extraction
NO_DIAGNOSTICS = FrameDiagnostics()

#: when annealing finds no rigid match, the triplet hypotheses over every blob stop at
#: the standard RANSAC count for this confidence (the inlier fraction read from the best
#: hypothesis so far: a count, not a clock, so the answer does not depend on the
#: machine's load) ...
FALLBACK_CONFIDENCE = 0.999
#: ... or after this many observed triplets, whichever comes first (every triplet of 50
#: blobs; at the default ``max_candidates`` of 32 there are at most 4960, ~5 ms warm, so
#: the cap binds only where more candidates are allowed). Until 2026-12 the cap was 100 ms of the
#: clock: a first call's warm-up on a loaded machine ran past it and the frame had no
#: pose, where a quiet machine found one
FALLBACK_MAX_TRIPLETS = 20_000
#: and its answer is taken only when its reflectors span a plane: the second singular
#: value of their catalog points at least this fraction of the first (a row of bright
#: fittings in a room matched the paper target's nearly collinear lower four markers,
#: ratio 0.11; a row's pose turns freely about it)
FALLBACK_MIN_SPREAD = 0.25
#: a pose whose attitude's largest sigma (the reported covariance's rotation block) is
#: beyond this is refused: that covariance is the fit's linearised at the pose, and at 3
#: sigma of 20 deg a rotation's second-order terms are half its first-order ones
#: (theta / 2 at theta = 60 deg); beyond, the ellipsoid no longer says where the pose
#: may lie. Seen with three markers nearly on one line, the rest of the target out of
#: view: 32 deg, the pose 25 deg off and 48 of its sigmas away through the position its
#: rotation drags along (the physics study's ``out of view`` family). Far targets reach it
#: too: at 15 m in 10 klx, 2 of 25 poses (their median 8 deg; none at 10-12 m)
MAX_ATTITUDE_SIGMA_DEG = 20.0


def undetermined_attitude(result: PoseResult) -> str:
    """Why the ok ``result``'s attitude is not determined by its matched reflectors (its
    largest attitude sigma beyond ``MAX_ATTITUDE_SIGMA_DEG``, or a covariance that is
    missing or not finite), or ''."""
    ids = [m.catalog_id for m in result.matched]
    cov = result.covariance
    if cov is None or not np.all(np.isfinite(cov)):
        return f"the pose on the matched reflectors {ids} has no finite covariance"
    sigma_deg = math.degrees(math.sqrt(max(np.linalg.eigvalsh(cov[:3, :3])[-1], 0)))
    if sigma_deg <= MAX_ATTITUDE_SIGMA_DEG:
        return ""
    return (
        f"attitude not determined by the matched reflectors {ids}: {sigma_deg:.0f} deg "
        f"(1 sigma) about one axis, beyond the {MAX_ATTITUDE_SIGMA_DEG:g} deg a linearised "
        "covariance describes (too few markers in view, or nearly on one line)"
    )


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
    timings_ms : per stage, and ``"total"`` the frame's (the pixel fit's ``"pixel fit"``
        and refused readings included); diagnostics : what extraction and persistence did
        (``FrameDiagnostics``; its fields read as properties: n_candidates, frames_used,
        motion, rejected, active_threshold_counts).
    R_svd, t_svd_mm : (3, 3), (3,) the weighted SVD pose (Eqs. 40-50) of the matched
        reflectors with the fit's weights, before refinement (``solve.Solution.T_svd``):
        the paper's §5.1 answer on the same measurements, to see what refinement did.
    pixel_fit : "" when the pixel-level fit did not run (``PipelineConfig.pixel_fit``),
        "ok" when ``R``, ``t_mm`` and ``covariance`` are its answer (where the fit could
        not check its own covariance by deleting each disc, as with three matched
        markers, the covariance also holds the centroid pose's:
        ``PixelFitResult.deletion_checked``), otherwise why it fell back to the centroid
        pose (which the result then carries).
    pixel_fit_left_out : with ``pixel_fit`` "ok", the markers the fit left out and why
        ("markers [6] left out: residual RMS ..."; ``PixelFitResult.left_out``), else "".
    range_offset : the range offset common to the reflectors that the pose's fit took
        out of their ranges, its posterior sigma and its prior's
        (``stages.pose.records.RangeOffset``; the pixel fit's when it holds): what the
        frame says of the camera's range offset (``stages.pose.range_bias``).
    distances_read_about_mm : None when the frame's distances were taken as measured;
        else the range they were read about, each moved by whole unambiguous ranges
        (the target beyond the range the camera's distances wrap at,
        ``stages.extraction.wrap``).
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
    diagnostics: FrameDiagnostics = field(default_factory=lambda: NO_DIAGNOSTICS)
    mode: Literal["acquisition", "tracking"] = "acquisition"
    R_svd: np.ndarray | None = None
    t_svd_mm: np.ndarray | None = None
    pixel_fit: str = ""
    range_offset: RangeOffset = NO_RANGE_OFFSET
    pixel_fit_left_out: str = ""
    distances_read_about_mm: float | None = None

    @property
    def n_matched(self) -> int:
        return len(self.matched)

    @property
    def n_candidates(self) -> int:
        return self.diagnostics.n_candidates

    @property
    def frames_used(self) -> int:
        return self.diagnostics.frames_used

    @property
    def motion(self) -> bool:
        return self.diagnostics.motion

    @property
    def rejected(self) -> tuple[RejectedBlob, ...]:
        return self.diagnostics.rejected

    @property
    def active_threshold_counts(self) -> float:
        return self.diagnostics.active_threshold_counts


def pose_shift_chi2(result: PoseResult, R: np.ndarray, t_mm: np.ndarray) -> float:
    """Squared Mahalanobis distance of the pose ``(R (3, 3), t_mm (3,))`` from
    ``result``'s pose under ``result.covariance`` (6, 6): the shift ``(rotation vector of
    R R_result^T rad, t - t_result mm)``, the covariance's parametrisation; inf without a
    covariance or when it is singular."""
    if result.R is None or result.t_mm is None or result.covariance is None:
        return math.inf
    shift = np.concatenate(
        [Rotation.from_matrix(R @ result.R.T).as_rotvec(), np.asarray(t_mm) - result.t_mm]
    )
    try:
        return float(shift @ np.linalg.solve(result.covariance, shift))
    except np.linalg.LinAlgError:
        return math.inf


def variance_factor(chi2: float, n_reflectors: int) -> float:
    """A-posteriori variance factor of the fit's covariance, dof = 3 n - 6.

    Above 1, chi^2 / dof: when the fit is worse than the measurement sigmas allow (a
    biased blob the outlier step could not single out, e.g. one of 4), the reported
    uncertainty grows with it instead of claiming sub-millimetre.

    Below 1, from ``NARROWING_MIN_REFLECTORS`` reflectors on: the upper
    ``NARROWING_CONFIDENCE`` bound of the variance factor that chi^2 allows,
    chi^2 / chi^2_dof(1 - confidence), when that is below 1, never below
    ``MIN_VARIANCE_FACTOR``. The per-reflector sigmas have floors for what no pixel
    statistic sees (``extraction.uncertainty``); on a sharp, bright frame the reflectors
    agree with each other far better than those floors say, and a covariance that
    ignores it is several times too wide (0.3 of the reported sigmas at 1 m on the
    simulator's ideal frames). The bound uses only what the residuals show, with the
    chance of a small chi^2 by luck priced in: it narrows only what the reflectors'
    mutual agreement measures, not the priors added beside it (a range offset or an
    image scale common to all of them leaves no residual).
    """
    dof = 3 * n_reflectors - 6
    if dof <= 0 or not np.isfinite(chi2):
        return 1.0
    if chi2 >= dof:
        return chi2 / dof
    if n_reflectors < NARROWING_MIN_REFLECTORS:
        return 1.0
    upper = chi2 / chi2_limit(dof, 1.0 - NARROWING_CONFIDENCE)
    return min(1.0, max(MIN_VARIANCE_FACTOR, upper))


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
        implementation: str = "compiled",
    ) -> None:
        """``range_correction``: the camera's calibrated range errors
        (``tofpose.calibration.range``), subtracted from each reflector's range before
        back-projection; None for a camera without one. ``ValueError`` when its
        per-pixel offsets are not of the camera's image size. ``covariance_scale``: the
        camera's covariance calibration (``tofpose.calibration.covariance``), applied to
        the reported covariance at the target's distance; None reports the model's.
        ``implementation``: "compiled" (the kernels, ``tofpose.core.compiled``) or "reference"
        (every stage's arithmetic by its plain NumPy/SciPy statement,
        ``tofpose.reference``: the A/B baseline of the whole chain, much slower; see
        ``tofpose.arithmetic`` for what it does not cover); ``ValueError`` for others."""
        arithmetic = arithmetic_for(implementation)  # ValueError naming the accepted ones
        offsets = None if range_correction is None else range_correction.pixel_offsets_mm
        if offsets is not None and offsets.shape != camera.shape:
            raise ValueError(
                f"the range correction's pixel offsets are {offsets.shape[0]} x "
                f"{offsets.shape[1]} px (rows x columns), the camera's images "
                f"{camera.shape[0]} x {camera.shape[1]}"
            )
        self.camera = camera
        self.implementation = implementation
        self.arithmetic: Arithmetic = arithmetic
        self.range_correction = range_correction
        self.covariance_scale = covariance_scale
        self._correction_kernel_args = correction_kernel_arguments(range_correction)
        self._camera_record = camera_record(camera)
        self.catalog = catalog
        self.config = config or PipelineConfig()
        self._sigma_constants = kernel_constants(
            SigmaFloors(
                centroid_sigma_floor_px=self.config.centroid_sigma_floor_px,
                range_sigma_floor_mm=self.config.range_sigma_floor_mm,
            )
        )
        self._persistence = Persistence(self.config.persistence)
        self._catalog_xyz = catalog.positions_mm
        self._catalog_d = catalog.diameters_mm
        self._catalog_ids = catalog.ids
        self._rng = np.random.default_rng(self.config.ransac_seed)
        self._solver = PoseSolver(
            camera, catalog, self.config.solve, range_correction, arithmetic=arithmetic.pose
        )
        self._track: TrackState | None = None
        # the range the distances are read about when the target is beyond the camera's
        # unambiguous range (``stages.extraction.wrap``), None: as measured; and what the
        # last frame's refused components suggest it is
        self._unwrap_about_mm: float | None = None
        self._wrap_suggestions: list[WrapSuggestion] = []
        # frames this pipeline was given: in tracking mode every ``reacquire_every``-th
        # frame of the stream is a full acquisition, whatever happened before, so the
        # schedule depends on the frame's index alone (``tofpose.batch.reprocess`` starts
        # a chunk at a multiple of it and catches up with the serial run)
        self._frames_seen = 0
        self._compiled_tracker = CompiledTracker(
            camera,
            catalog,
            self.config.solve,
            self.config.tracking,
            self._solver,
            self._persistence,
            range_correction,
            arithmetic=arithmetic.tracking,
        )

    def reset(self) -> None:
        """Forget multi-frame history (call when the stream is discontinuous)."""
        self._forget_history()
        self._unwrap_about_mm = None

    def state_digest(self) -> bytes:
        """A digest (16 bytes) of everything a frame leaves for the next ones: the
        persistence history, the tracking state, the RANSAC generator and (in tracking
        mode) the stream's position in the re-acquisition period. Two pipelines
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
            h.update(
                np.array(
                    [
                        tr.threshold_counts,
                        tr.background_counts,
                        tr.dark_counts,
                        tr.frames_since_acquisition,
                        tr.psf_sigma_px,
                    ],
                    float,
                ).tobytes()
            )
        h.update(repr(self._rng.bit_generator.state).encode())
        if self._unwrap_about_mm is not None:
            h.update(np.float64(self._unwrap_about_mm).tobytes())
        if self.config.tracking.enabled:  # where the stream is in the re-acquisition period
            h.update(
                (self._frames_seen % self.config.tracking.reacquire_every).to_bytes(4, "little")
            )
        return h.digest()

    # ------------------------------------------------------------------------------------
    def process(
        self, gray: np.ndarray, distance_mm: np.ndarray, time_s: float | None = None
    ) -> PoseResult:
        """Estimate the pose from one (gray, distance) frame pair.

        Raises ``FrameError`` (a ValueError) for arrays of the wrong shape or dtype;
        every other failure is an ``ok = False`` result with a reason. With
        ``config.pixel_fit.enabled`` an ok pose is refined on the matched markers' pixels
        (``PoseResult.pixel_fit`` says how that went). A frame refused because its
        components have the catalog's sizes only at their distances plus whole unambiguous
        ranges (the target beyond the range the camera's distances wrap at) is measured
        again with its distances read so (``_measure_unwrapped``; not on a camera that
        states ``unwrapped_range_mm``, which unwraps its own or reports nothing beyond).
        """
        result = self._process(gray, distance_mm, time_s)
        if not result.ok and self._wrap_suggestions:
            result = self._measure_unwrapped(gray, distance_mm, time_s, result)
        about = self._unwrap_about_mm
        if result.ok and result.t_mm is not None and about is not None:
            # the reading follows the target, and ends where the distances no longer wrap
            range_mm = float(np.linalg.norm(result.t_mm))
            result = replace(result, distances_read_about_mm=about)
            near = range_mm <= 0.5 * self.camera.unambiguous_range_mm
            self._unwrap_about_mm = None if near else range_mm
        if not (self.config.pixel_fit.enabled and result.ok):
            return result
        if result.distances_read_about_mm is not None:
            distance_mm = unwrap_about(
                np.asarray(distance_mm, float),
                result.distances_read_about_mm,
                self.camera.unambiguous_range_mm,
            )
        return self._refine_on_pixels(result, gray, distance_mm)

    def _measure_unwrapped(
        self, gray: np.ndarray, distance_mm: np.ndarray, time_s: float | None, refused: PoseResult
    ) -> PoseResult:
        """The frame measured again, from a fresh start, with its distances read about
        each range ``_wrap_suggestions`` found in turn (``stages.extraction.wrap``, at most
        ``MAX_READINGS``); the first ok result with more reflectors than a match needs
        (a reading is a guess: a minimal match, checked by its own few distances, is not
        taken on it). When none is (or a reading raises), the pipeline's state and
        ``refused`` as they were: the first reading stands, nothing of the others is kept.
        The result's ``timings_ms`` hold the refused readings' time as ``"refused
        reading"``, and its ``"total"`` every reading's."""
        suggestions = self._wrap_suggestions[:MAX_READINGS]
        before = (
            self._persistence.snapshot(),
            self._track,
            self._rng.bit_generator.state,
            self._frames_seen,
            self._unwrap_about_mm,
        )
        spent_ms = refused.timings_ms.get("total", 0.0)
        kept = False
        try:
            for suggestion in suggestions:
                self._forget_history()
                self._frames_seen = before[3] - 1  # the same frame of the stream
                self._unwrap_about_mm = suggestion.about_mm
                again = self._process(gray, distance_mm, time_s)
                if again.ok and again.n_matched > self.config.matching.min_matches:
                    kept = True
                    total = again.timings_ms.get("total", 0.0) + spent_ms
                    timings = {**again.timings_ms, "refused reading": spent_ms, "total": total}
                    return replace(again, timings_ms=timings)
                spent_ms += again.timings_ms.get("total", 0.0)
        finally:
            if not kept:
                history, self._track, rng_state, self._frames_seen, self._unwrap_about_mm = before
                self._persistence.restore(history)
                self._rng.bit_generator.state = rng_state
                self._wrap_suggestions = suggestions
        return refused

    def _forget_history(self) -> None:
        """What a frame leaves for the next ones, forgotten (``reset`` but the reading of
        the distances, which a saturated or dark frame says nothing of)."""
        self._persistence.reset()
        self._track = None

    def _refine_on_pixels(
        self, result: PoseResult, gray: np.ndarray, distance_mm: np.ndarray
    ) -> PoseResult:
        """The pixel-level fit (``stages.pixelfit``) from the ok ``result``'s pose and
        matches: its pose and covariance when it holds, else ``result`` with the reason."""
        assert result.R is not None and result.t_mm is not None  # an ok result has both
        cfg = self.config.pixel_fit
        t0 = time.perf_counter()
        ranges_mm = np.array([np.linalg.norm(m.point_mm) for m in result.matched])
        offset_sigma_mm = (
            self._solver.range_bias_sigma_mm(ranges_mm)
            if self.config.solve.estimate_range_offset
            else 0.0
        )
        offset_mean_mm = (
            float(self.config.range_offset_mean_mm)
            if self.config.solve.estimate_range_offset
            else 0.0
        )
        fit = fit_pose_to_pixels(
            np.asarray(gray),
            self._range_corrected(np.asarray(gray), np.asarray(distance_mm)),
            self.camera,
            self.catalog,
            result.R,
            result.t_mm,
            [m.catalog_id for m in result.matched],
            noise=PixelNoise(
                modulation_frequency_hz=self.camera.modulation_frequency_hz,
                full_scale_counts=self.camera.full_scale_counts,
            ),
            # a free offset when asked; else the pose fit's prior on it (none when the
            # camera states a range-bias sigma of 0)
            fit_range_offset=cfg.fit_range_offset or offset_sigma_mm > 0,
            range_offset_sigma_mm=float("inf") if cfg.fit_range_offset else offset_sigma_mm or 1.0,
            range_offset_mean_mm=offset_mean_mm,
            max_marker_rms_sigma=cfg.max_marker_rms_sigma,
            implementation=self.implementation,
        )
        fit_ms = 1e3 * (time.perf_counter() - t0)
        total_ms = result.timings_ms.get("total", 0.0) + fit_ms  # the frame's, fit included
        timings = {**result.timings_ms, "pixel fit": fit_ms, "total": total_ms}
        if not fit.ok or fit.covariance is None:
            return replace(result, pixel_fit=fit.reason or "no covariance", timings_ms=timings)
        shift2 = pose_shift_chi2(result, fit.R, fit.t_mm)
        if not shift2 <= cfg.max_shift_chi2:
            why = (
                f"the fitted pose lies {np.sqrt(shift2):.1f} sigma from the centroid pose "
                f"(at most {np.sqrt(cfg.max_shift_chi2):.1f}): another answer, not a "
                "refinement"
                if np.isfinite(shift2)
                else "the centroid pose's covariance is singular: the fit cannot be checked "
                "against it"
            )
            return replace(result, pixel_fit=why, timings_ms=timings)
        return replace(
            result,
            R=fit.R,
            t_mm=fit.t_mm,
            euler_deg=facing_euler_deg(fit.R),
            quaternion_wxyz=quaternion_wxyz_from_rotation(fit.R),
            covariance=self._pixel_fit_covariance(fit, result),
            pixel_fit="ok",
            pixel_fit_left_out=(
                f"markers {fit.left_out.tolist()} left out: {fit.left_out_reason}"
                if len(fit.left_out)
                else ""
            ),
            timings_ms=timings,
            range_offset=RangeOffset(
                fit.range_offset_mm,
                fit.range_offset_sigma_mm,
                # a free offset: a prior of infinite sigma (the frame's likelihood is then
                # its posterior)
                float("inf") if cfg.fit_range_offset else offset_sigma_mm,
                offset_mean_mm,
            ),
        )

    def _pixel_fit_covariance(self, fit: PixelFitResult, result: PoseResult) -> np.ndarray:
        """(6, 6) the covariance reported with the pixel fit's pose: the fit's, and where
        the fit could not check it by deleting each disc (``fit.deletion_checked``: three
        matched markers, or a deletion that leaves the pose undetermined) the envelope of
        the fit's and the centroid pose's ``result`` (``pose.covariance_envelope``): a
        claim no narrower than one that was checked."""
        assert fit.covariance is not None and result.covariance is not None
        if fit.deletion_checked:
            return fit.covariance
        return self.arithmetic.pose.covariance_envelope(fit.covariance, result.covariance)

    def _range_corrected(self, gray: np.ndarray, distance_mm: np.ndarray) -> np.ndarray:
        """``distance_mm`` (H, W) less the calibrated range error of each pixel
        (``range_correction``; the pixel fit reads whole pixels, the §3 stages correct
        each reflector's range in their kernel instead); unchanged without one."""
        c = self.range_correction
        if c is None:
            return distance_mm
        valid = np.isfinite(distance_mm)
        out = distance_mm.astype(float, copy=True)
        index = np.flatnonzero(valid)
        out.ravel()[index] -= c.error_mm(distance_mm.ravel()[index], gray.ravel()[index], index)
        return out

    def _process(
        self, gray: np.ndarray, distance_mm: np.ndarray, time_s: float | None
    ) -> PoseResult:
        cfg = self.config
        timer = _Timer()
        g, d = check_frame(self.camera, gray, distance_mm)
        self._wrap_suggestions = []
        if self._unwrap_about_mm is not None:  # a frame read about a range (a far target)
            wrap_mm = self.camera.unambiguous_range_mm
            if self._unwrap_about_mm > 0.5 * wrap_mm:
                d = unwrap_about(d, self._unwrap_about_mm, wrap_mm)
        frame_number = self._frames_seen
        self._frames_seen += 1
        track = self._track
        self._track = None  # set again below by a confident pose
        if (
            cfg.tracking.enabled
            and track is not None
            and frame_number % cfg.tracking.reacquire_every != 0
        ):
            tracked = self._process_tracking(g, d, time_s, track, timer)
            if tracked is not None:
                return tracked
            timer.lap("tracking fallback")
        stats = self.arithmetic.extraction.frame_levels(
            g, cfg.extraction, saturated_counts=self.camera.full_scale_counts
        )
        # thresholds above a lit plate or wall, not inside its noise
        stats = thresholds_above_surface(
            stats, g, d, self.camera.fx, self._catalog_d, cfg.extraction, self.camera.count_scale
        )
        timer.lap("levels")

        def fail(reason: str, unmatched=(), diagnostics=NO_DIAGNOSTICS) -> PoseResult:
            return PoseResult(
                ok=False,
                reason=reason,
                time_s=time_s,
                timings_ms=timer.total(),
                unmatched=list(unmatched),
                diagnostics=diagnostics,
            )

        if stats.saturated_fraction > 0.5:
            self._forget_history()
            return fail(f"frame saturated: {stats.saturated_fraction:.0%} of pixels at full scale")
        if stats.i_max - stats.background < cfg.extraction.min_contrast_counts:
            self._forget_history()
            return fail(
                f"no reflector contrast: brightest pixel {stats.i_max:.0f} counts over a "
                f"background of {stats.background:.0f} (all-dark frame?)"
            )
        found, blobs = self._candidates(g, d, stats, timer)
        stats = found.stats  # I_t as applied (after the N_max cap)
        # A, for the pose check; the lens blur for the centroid errors' prior
        active = ThresholdedFrame(g, stats.raw_threshold, stats.psf_sigma_px)
        # The motion gate compares the cheap moment centroids of find_candidate_blobs;
        # the precise centroids and ranges are measured once, on the combined frames.
        meas, unmatched, n_kept, pinfo = self._measure(
            blobs, g, d, stats.background, stats.dark_level
        )
        timer.lap("measurement")  # §3.4, Eqs. 7-9 and the sigmas
        diag = FrameDiagnostics(
            n_candidates=n_kept,
            frames_used=pinfo.frames_used,
            motion=pinfo.motion,
            rejected=tuple(found.rejected),
            active_threshold_counts=stats.raw_threshold,
            surface_level_counts=stats.surface_level,
        )
        if len(meas.range_mm) < cfg.matching.min_matches:
            self._wrap_suggestions = self._suggest_wraps(found.wrong_size)
            return fail(
                f"found {len(meas.range_mm)} candidate reflector(s) with a valid range "
                f"(of {n_kept} blobs), need {cfg.matching.min_matches}"
                + self._size_hint(found.wrong_size)
                + self._saturation_hint(g, blobs),
                unmatched=unmatched + meas.as_unmatched(),
                diagnostics=diag,
            )
        m = self._match(meas)
        from_hypotheses = False
        if not m.ok and cfg.triplet_fallback and cfg.matcher == "annealing":
            # many look-alike blobs (glints, other reflectors) can leave annealing's soft
            # assignment without a rigid match although one is there: the triplet
            # hypotheses over every blob (the RANSAC matcher's search) are tried instead
            hypotheses = self._match_ransac(
                meas.y_mm,
                meas.weights,
                max_triplets=FALLBACK_MAX_TRIPLETS,
                confidence=FALLBACK_CONFIDENCE,
            )
            # at least one reflector beyond the fewest: a hypothesis of 3 is checked by
            # its own 3 distances only (on 8 m frames with every physics knob on, one
            # such pose was 5.8 deg off at 30 of its chi^2)
            if (
                hypotheses.ok
                and len(hypotheses.pairs) > cfg.matching.min_matches
                and self._spread_ratio(hypotheses.pairs[:, 1]) >= FALLBACK_MIN_SPREAD
            ):
                m, from_hypotheses = hypotheses, True
        timer.lap("matching")
        if not m.ok:
            self._wrap_suggestions = self._wrap_readings(found, meas)
            return fail(
                f"matching failed: {m.reason}"
                + self._wrap_clause()
                + self._saturation_hint(g, blobs),
                unmatched=unmatched + meas.as_unmatched(),
                diagnostics=diag,
            )
        # a pose from hypotheses over every blob must also leave no reflector it predicts
        # clearly visible on a dark part of the frame: bright clutter (a room's fittings)
        # can hold four points rigidly like the catalog's, it does not hold the rest
        solved = self._solve_with_fallback(meas, m, active, dark_check_all=from_hypotheses)
        timer.lap("refine")
        if isinstance(solved, Rejected):
            self._wrap_suggestions = self._wrap_readings(found, meas)
            return fail(
                solved.reason + self._wrap_clause() + self._saturation_hint(g, blobs),
                unmatched=unmatched + meas.as_unmatched(),
                diagnostics=diag,
            )
        saturated = blobs_at_full_scale(
            g, meas.blobs, full_scale_counts=self.camera.full_scale_counts
        )
        result = self._pose_result(solved, meas, saturated, unmatched, time_s, timer, diag)
        why = undetermined_attitude(result) or self._merged_in_minimal_pose(solved, meas)
        if why:
            return fail(why, unmatched=unmatched + meas.as_unmatched(), diagnostics=diag)
        self._track = TrackState(
            R=solved.T_camera_target.R,
            t_mm=solved.T_camera_target.t_mm,
            threshold_counts=stats.raw_threshold,
            background_counts=stats.background,
            dark_counts=stats.dark_level,
            psf_sigma_px=stats.psf_sigma_px,
        )
        return result

    # -- stages ---------------------------------------------------------------------------
    def _candidates(self, g, d, stats, timer) -> tuple[CandidateBlobs, list[Blob]]:
        """§3.1-§3.3: candidate blobs through the gates, then ellipse confirmation (which
        may split merged components); returns the extraction record and the blobs."""
        cfg = self.config
        found = self.arithmetic.extraction.find_candidate_blobs(
            g, d, self.camera, self._catalog_d, cfg.extraction, stats
        )
        timer.lap("blobs")
        blobs = found.accepted
        if cfg.ellipse_confirmation:
            blobs = confirm_ellipses(
                blobs,
                found.oversize,
                g,
                found.stats,
                fx_px=self.camera.fx,
                catalog_diameters_mm=self._catalog_d,
                config=cfg.extraction,
                arithmetic=self.arithmetic.ellipses,
            )
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
        (``stages.persistence.kernels.measure.measure_and_back_project``): the blobs
        combined with the consistent persistence history (the frame is then committed to
        it), their
        centroids (Eq. 19) and ranges (Eq. 20) measured, the calibrated range correction
        applied, and those with a range back-projected (Eq. 8) with their sigmas and the
        weights of Eq. 21. Returns the ``Measurements`` of the kept blobs with a range,
        (u, v, range) of the kept ones without, how many were kept, and what persistence
        combined."""
        cam, persistence, ar = self.camera, self._persistence, self.arithmetic
        lists = blob_lists(blobs)
        frame = FrameRecord(gray=g, distance=d, background=float(background), dark=float(dark))
        m = ar.persistence.measure_and_back_project(
            frame,
            lists,
            persistence.history(g, d),
            self._camera_record,
            self._correction_kernel_args,
            self._sigma_constants,
        )
        n_used, motion, keep, rho = m.n_used, m.motion, m.keep, m.rho
        persistence.commit(lists.centroids, lists.flat, g, d, n_used, motion)
        unranged = [
            (m.uv[j, 0], m.uv[j, 1], rho[j]) for j in np.flatnonzero(keep & ~np.isfinite(rho))
        ]
        ranged_blobs = tuple(blobs[j] for j in m.ranged.tolist())
        c = m.candidates
        uv, rho_r, y, w, sp, sr = (
            c.uv_px,
            c.range_mm,
            c.y_mm,
            c.weights,
            c.sigma_px,
            c.sigma_range_mm,
        )
        fitted = [a for a, b in enumerate(ranged_blobs) if b.fitted_uv is not None]
        if fitted:  # centres from the pair fit replace the halves' moment centroids
            uv, y, w, sr = uv.copy(), y.copy(), w.copy(), sr.copy()
            uv[fitted] = [ranged_blobs[a].fitted_uv for a in fitted]
            # a half's range mixes the neighbour's and the surround's light at the cut:
            # its bearing is used, its range only as a weak constraint
            sr[fitted] = np.maximum(sr[fitted], UNCALIBRATED_RANGE_SIGMA_MM)
            y[fitted] = ar.persistence.bearings(cam, uv[fitted]) * rho_r[fitted, None]  # Eq. 8
            w[fitted] = 1.0 / (sr[fitted] ** 2 + (rho_r[fitted] * sp[fitted] / cam.fx) ** 2)
        area = np.array([b.area_px for b in ranged_blobs], np.int64)
        meas = Measurements(ranged_blobs, area, uv, rho_r, y, w, sp, sr, c.mixing)
        n_kept = int(keep.sum())
        return meas, unranged, n_kept, PersistenceInfo(1 + n_used, motion, len(blobs) - n_kept)

    def _match(self, meas: Measurements) -> MatchResult:
        """§4: deterministic annealing (with the size term) or, configured, RANSAC."""
        cfg = self.config
        if cfg.matcher == "ransac":
            return self._match_ransac(meas.y_mm, meas.weights)
        diam = np.array([self._apparent_diameter_px(b) for b in meas.blobs])
        return match_reflectors(
            meas.y_mm,
            self._catalog_xyz,
            cfg.matching,
            observed_diameter_mm=diam * meas.range_mm / self.camera.fx,
            catalog_diameter_mm=self._catalog_d,
            weights=meas.weights,
            arithmetic=self.arithmetic.matching,
        )

    def _solve_with_fallback(
        self, meas: Measurements, m: MatchResult, active, *, dark_check_all: bool = False
    ):
        """§5 on the matched pairs; when annealing's assignment gives an implausible pose
        (a mirror image), the exhaustive triplet hypotheses restricted to physically
        possible poses (ours) are solved instead. ``dark_check_all``: verify with the
        dark check whatever the number matched (``PoseSolver.verify``)."""
        cfg = self.config
        solved = self._solver.solve(
            m.pairs, meas, m.alpha_mm, active, dark_check_all=dark_check_all
        )
        if not (
            isinstance(solved, Rejected)
            and solved.implausible
            and cfg.triplet_fallback
            and cfg.matcher == "annealing"
        ):
            return solved
        tol = cfg.matching.pair_tolerance_mm(m.alpha_mm, meas.weights)
        pairs = match_by_triplets(
            meas.y_mm,
            self._catalog_xyz,
            m.alpha_mm,
            tol,
            self._solver.facing,
            weights=meas.weights,
            min_matches=cfg.matching.min_matches,
            arithmetic=self.arithmetic.matching,
        )
        if not len(pairs):
            return solved
        return self._solver.solve(pairs, meas, m.alpha_mm, active, dark_check_all=dark_check_all)

    def _process_tracking(self, g, d, time_s, track: TrackState, timer) -> PoseResult | None:
        """Tracking mode (``tofpose.stages.tracking.tracking``,
        ``tofpose.stages.tracking.tracking_frame``): reflectors
        searched only in windows around their predicted images, correspondences known,
        in one compiled call; None means "fall back to the full acquisition pass", and
        leaves no trace in the persistence history."""
        before = self._persistence.snapshot()  # the tracker commits the frame it tracks
        tracked = self._compiled_tracker.track(g, d, track)
        timer.lap("tracking")
        if tracked is None:
            return None
        result = self._tracked_result(tracked, time_s, timer, track)
        if result is None:  # refused: the acquisition pass commits the frame itself
            self._persistence.restore(before)
        return result

    def _tracked_result(
        self, tracked: Tracked, time_s, timer, track: TrackState
    ) -> PoseResult | None:
        """The ok result of a tracked frame; the track moves on to its pose. None (the
        acquisition pass then runs) when its attitude is not determined
        (``undetermined_attitude``) or its fewest markers hold a merged blob
        (``_merged_in_minimal_pose``)."""
        solved, meas, info = tracked.solution, tracked.measurements, tracked.persistence
        diag = FrameDiagnostics(
            n_candidates=len(meas.range_mm),
            frames_used=info.frames_used,
            motion=info.motion,
            active_threshold_counts=track.threshold_counts,
        )
        result = self._pose_result(
            solved, meas, tracked.saturated, [], time_s, timer, diag, mode="tracking"
        )
        if undetermined_attitude(result) or self._merged_in_minimal_pose(solved, meas):
            return None  # the acquisition pass says why
        self._track = TrackState(
            R=solved.T_camera_target.R,
            t_mm=solved.T_camera_target.t_mm,
            threshold_counts=track.threshold_counts,
            background_counts=track.background_counts,
            dark_counts=track.dark_counts,
            psf_sigma_px=track.psf_sigma_px,
            frames_since_acquisition=track.frames_since_acquisition + 1,
        )
        return result

    def _pose_result(
        self,
        solved: Solution,
        meas: Measurements,
        saturated: np.ndarray,
        unmatched,
        time_s,
        timer,
        diagnostics: FrameDiagnostics,
        mode: Literal["acquisition", "tracking"] = "acquisition",
    ) -> PoseResult:
        """The ok result of a ``Solution`` found from ``meas``; ``saturated`` (n,) bool
        whether each of ``meas``' n blobs has a pixel at full scale; ``unmatched`` lists
        the blobs without a range, the unmatched candidates are added."""
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
        res, rms = self.arithmetic.pose.point_residuals_mm(x, y_m, R, t)
        per_reflector = zip(
            self._catalog_ids[i_idx].tolist(),
            uv_m,
            y_m,
            res.tolist(),
            rho_m.tolist(),
            area[k_idx].tolist(),
            sig_px[k_idx].tolist(),
            obs.sigma_range_mm.tolist(),
            saturated[k_idx].tolist(),
            strict=True,
        )
        matched = [
            MatchedReflector(
                catalog_id=i,
                centroid_uv=c,
                point_mm=y,
                residual_mm=r,
                distance_mm=d,
                area_px=a,
                centroid_sigma_px=sp,
                range_sigma_mm=sr,
                saturated=sat,
            )
            for i, c, y, r, d, a, sp, sr, sat in per_reflector
        ]
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
            diagnostics=diagnostics,
            mode=mode,
            R_svd=None if solved.T_svd is None else solved.T_svd.R,
            t_svd_mm=None if solved.T_svd is None else solved.T_svd.t_mm,
            range_offset=ml.range_offset,
        )

    def _merged_in_minimal_pose(self, solved: Solution, meas: Measurements) -> str:
        """Why a pose on the fewest reflectors (``matching.min_matches``: no redundancy
        to show a biased one) cannot stand, or '': a catalog reflector it did not match,
        in front of the camera and not seen as a candidate of its own, projects onto a
        matched blob (nearer its centroid than the blob's equivalent radius plus the
        reflector's own image radius). That blob then holds
        two reflectors imaged as one (7 and 8 of the paper target merge at long range),
        and its centroid lies between them: at 8 m with the rest of the target out of
        view such a pose was 7 deg off at 10 of its sigmas."""
        obs = solved.observations
        if len(obs.i_idx) > self.config.matching.min_matches:
            return ""
        T = solved.T_camera_target
        others = np.setdiff1d(np.arange(len(self._catalog_ids)), obs.i_idx)
        points = self._catalog_xyz[others] @ T.R.T + T.t_mm
        front = points[:, 2] > 0
        others, points = others[front], points[front]
        if not len(others):
            return ""
        uv = self.camera.project(points)
        own_radius_px = 0.5 * self.camera.fx * self._catalog_d[others] / points[:, 2]
        # a reflector seen as a blob of its own (an unmatched candidate on its image) is
        # not inside another's
        unmatched = np.setdiff1d(np.arange(len(meas.range_mm)), obs.k_idx)
        if len(unmatched):
            near = np.linalg.norm(uv[:, None, :] - meas.uv_px[None, unmatched], axis=2)
            seen = np.any(near < own_radius_px[:, None], axis=1)
            uv, own_radius_px, others = uv[~seen], own_radius_px[~seen], others[~seen]
        blob_radius_px = np.sqrt(meas.area_px[obs.k_idx] / np.pi)
        gap = np.linalg.norm(uv[:, None, :] - obs.uv_px[None, :, :], axis=2)
        overlap = gap < blob_radius_px[None, :] + own_radius_px[:, None]
        if not overlap.any():
            return ""
        o, j = np.argwhere(overlap)[0]
        return (
            f"reflector {int(self._catalog_ids[others[o]])} would overlap the blob "
            f"matched as {int(self._catalog_ids[obs.i_idx[j]])}: two reflectors imaged as "
            f"one, whose centroid lies between them, and {len(obs.i_idx)} matched "
            "reflectors leave nothing to tell the pose it biases"
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
            cov = self.arithmetic.pose.covariance_envelope(cov, ml.leave_one_out_covariance)
        if self.covariance_scale is not None:
            cov = cov * self.covariance_scale.factor_at(math.sqrt(float(t_mm @ t_mm)))
        return cov

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
            + (self._wrap_hint(wrong_size) or "is the right catalog active?")
        )

    def _suggest_wraps(self, wrong_size) -> list[WrapSuggestion]:
        """``stages.extraction.wrap.suggested_ranges_mm`` of the components the size window
        refused (``WrongSizeBlob``), at least as many as a match needs, up to
        ``max_reading_mm``; none on a camera that states ``unwrapped_range_mm``."""
        if not wrong_size or self.camera.unwrapped_range_mm is not None:
            return []
        return suggested_ranges_mm(
            wrong_size,
            self.camera.fx,
            self._catalog_d,
            self.config.extraction,
            self.camera.unambiguous_range_mm,
            self.config.matching.min_matches,
            max_reading_mm(self.camera.fx, self._catalog_d),
        )

    def _wrap_readings(self, found: CandidateBlobs, meas: Measurements) -> list[WrapSuggestion]:
        """For a frame whose candidates give no pose where they read: the readings the
        refused components' sizes suggest (``_suggest_wraps``), else
        ``stages.extraction.wrap.readings_beyond`` of the candidates' ranges (either way
        from a frame already read about a range), up to ``max_reading_mm``; none on a
        camera that states ``unwrapped_range_mm``."""
        by_size = self._suggest_wraps(found.wrong_size)
        if by_size or self.camera.unwrapped_range_mm is not None:
            return by_size
        return readings_beyond(
            np.asarray(meas.range_mm, float),
            self.camera.unambiguous_range_mm,
            max_reading_mm(self.camera.fx, self._catalog_d),
        )

    def _wrap_clause(self) -> str:
        """A clause naming the readings of the distances tried (``_wrap_suggestions``) for a
        frame refused by matching or the pose's checks, or ''."""
        if not self._wrap_suggestions:
            return ""
        wrap_mm = self.camera.unambiguous_range_mm
        tried = ", ".join(f"{s.about_mm / 1000:.1f}" for s in self._wrap_suggestions[:MAX_READINGS])
        return (
            f"; the camera's distances wrap at {wrap_mm / 1000:.2f} m "
            f"({self.camera.modulation_frequency_hz / 1e6:g} MHz), and no pose held with "
            f"them read about {tried} m either: if the target is beyond that range, bring "
            "it nearer or use a lower modulation frequency"
        )

    def _wrap_hint(self, wrong_size) -> str:
        """What to say when most of the blobs ``wrong_size`` have the catalog's size only
        at their range plus (or less) whole unambiguous ranges (``_wrap_suggestions``, found
        on this frame): the target is beyond the range the camera's distances wrap at (or
        was, and came nearer). '' otherwise."""
        if not self._wrap_suggestions:
            return ""
        s = self._wrap_suggestions[0]
        wrap_mm = self.camera.unambiguous_range_mm
        way = "further" if s.wraps > 0 else "nearer"
        return (
            f"they have the catalog's sizes at {abs(s.wraps)} unambiguous range(s) {way} "
            f"(about {s.about_mm / 1000:.1f} m), where the camera's distances wrap "
            f"({wrap_mm / 1000:.2f} m at {self.camera.modulation_frequency_hz / 1e6:g} MHz), "
            "but no pose held with the distances read so; bring the target within "
            f"{wrap_mm / 1000:.2f} m or use a lower modulation frequency"
        )

    def _saturation_hint(self, gray: np.ndarray, blobs: list[Blob]) -> str:
        """A clause counting the candidate ``blobs`` with a pixel at the camera's full
        scale in ``gray`` (H, W) and what to do about it, or ''."""
        full_scale = self.camera.full_scale_counts
        n = int(np.count_nonzero(blobs_at_full_scale(gray, blobs, full_scale_counts=full_scale)))
        if n == 0:
            return ""
        return (
            f"; {n} candidate{' saturates' if n == 1 else 's saturate'} (gray at full scale "
            f"{full_scale:.0f}): lower the integration time or turn auto exposure on"
        )

    def _match_ransac(
        self,
        y: np.ndarray,
        w: np.ndarray,
        *,
        budget_ms: float | None = None,
        max_triplets: int | None = None,
        confidence: float | None = None,
    ) -> MatchResult:
        """Random triplet hypotheses over all blobs, best inlier count, until the standard
        RANSAC count for ``confidence`` is reached or the budget is spent: at most
        ``max_triplets`` observed triplets when given (no clock: the same frames give the
        same answer on any machine), else the time budget ``budget_ms`` (defaults:
        ``ransac_time_budget_ms``, ``ransac_confidence``); ``iterations`` of the result =
        observed triplets tried."""
        if max_triplets is not None and budget_ms is not None:
            raise ValueError("_match_ransac: give max_triplets or budget_ms, not both")
        cfg = self.config
        stats: dict = {}
        budget = cfg.ransac_time_budget_ms if budget_ms is None else budget_ms
        triplets = random_triplets(len(y), self._rng)
        if max_triplets is not None:
            triplets, budget = triplets[:max_triplets], None
        confidence = cfg.ransac_confidence if confidence is None else confidence
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
            observed_triplets=triplets,
            deadline_s=None if budget is None else time.perf_counter() + budget / 1000.0,
            confidence=confidence,
            stats=stats,
            arithmetic=self.arithmetic.matching,
        )
        matched = set(pairs[:, 0].tolist())
        unmatched = [k for k in range(len(y)) if k not in matched]
        reason = "" if len(pairs) else "no triplet hypothesis with enough inliers"
        tried = stats.get("triplets", 0)
        return MatchResult(pairs, unmatched, np.zeros((len(y), 0)), tried, alpha, reason)

    def _spread_ratio(self, catalog_idx: np.ndarray) -> float:
        """Second over first singular value of the catalog points ``catalog_idx`` (m,)
        about their mean: near 0 for reflectors along a line, about which their pose
        turns freely."""
        x = self._catalog_xyz[catalog_idx]
        s = np.linalg.svd(x - x.mean(axis=0), compute_uv=False)
        return float(s[1] / s[0]) if s[0] > 0 else 0.0

    # ------------------------------------------------------------------------------------
    @staticmethod
    def _apparent_diameter_px(b: Blob) -> float:
        if b.ellipse is not None:
            return float(max(b.ellipse[1]))
        _, _, bw, bh = b.bbox
        return float(max(bw, bh, 2.0 * np.sqrt(b.area_px / np.pi)))
