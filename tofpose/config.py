"""The pipeline's configuration: one frozen record per stage, composed by
``PipelineConfig``.

``ExtractionConfig`` (§3.1-§3.3), ``PersistenceConfig`` (§3.4), ``MatchingConfig`` (§4),
``SolveConfig`` (§5) and ``TrackingConfig`` (tracking mode) are what each stage receives;
``PipelineConfig`` holds the first four stages' records and the §5 settings as its own
fields (the names users set: ``PipelineConfig(refinement="los")``), and hands each stage
its record (``PipelineConfig.solve``). This module imports no stage, so every stage can
import its own record without an import circle.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Literal

import numpy as np

from tofpose.core.robust import median_1d


@dataclass(frozen=True)
class ExtractionConfig:
    """Parameters of §3. Relative thresholds are fractions of the frame's contrast
    ``I_max - background``; ``*_abs`` values, when set, replace them (paper preset).

    Attributes
    ----------
    raw_threshold_rel : I_t = bg + rel * (I_max - bg) (§3.1.1; paper 0.38 * I_max).
    noise_floor_sigma : I_t is at least bg + this many background noise sigmas.
    min_contrast_counts : frames whose I_max - bg is below this are "all dark".
    n_max : N_max, cap on the active pixel set, dimmest discarded first (§3.1.1).
    peak_rel : I_peak = bg + peak_rel * (I_max - bg) (criterion 1, Eq. 16).
    nlog_peak_rel : J_peak as a fraction of the blob's own peak contrast; the nLoG is
        scale-normalised (sigma^2 * -LoG), so a matched disc reaches 2/e ~ 0.74 (Eq. 18).
    nlog_floor_rel : J_t as a fraction of the blob's peak contrast (Eq. 17).
    max_tilt_deg : largest reflector tilt to accept; sets the eccentricity gate
        (e <= sin(tilt)) and the smallest accepted size (cos(tilt) shrink).
    size_tolerance : multiplicative slack on the predicted diameter window.
    size_margin_px : additive slack in pixels (blur, thresholding, quantisation).
    min_area_px : smallest blob in pixels.
    q_max : maximum penalty score (§3.4, paper 0.9).
    max_candidates : L, keep the L best candidates.
    ellipse_min_points : PC, fewest edge points for an ellipse fit (§3.3).
    ellipse_max_residual_px : RMS distance of edge points from the fitted ellipse above
        which a blob is not confirmed as a projected disc.
    surface_threshold : raise I_t and I_peak above a lit surface around the markers (a
        bright plate, a wall) when one is lit (``stages.extraction.surface``); off, the
        thresholds are the paper's relative ones over the frame's background alone.
    h_min_px, h_max_px, raw_threshold_abs, peak_abs, nlog_peak_abs, nlog_floor_abs,
    nlog_sigma_px : paper preset only (fixed numbers, no range adaptivity).
    """

    raw_threshold_rel: float = 0.15
    noise_floor_sigma: float = 6.0
    min_contrast_counts: float = 25.0
    n_max: int = 120 * 100
    peak_rel: float = 0.25
    nlog_peak_rel: float = 0.15
    nlog_floor_rel: float = -0.05
    max_tilt_deg: float = 72.0
    size_tolerance: float = 1.35
    size_margin_px: float = 1.5
    min_area_px: int = 1
    q_max: float = 0.9
    max_candidates: int = 32
    ellipse_min_points: int = 6
    ellipse_max_residual_px: float = 0.8
    surface_threshold: bool = True
    h_min_px: int | None = None
    h_max_px: int | None = None
    raw_threshold_abs: float | None = None
    peak_abs: float | None = None
    nlog_peak_abs: float | None = None
    nlog_floor_abs: float | None = None
    nlog_sigma_px: float | None = None

    @staticmethod
    def paper() -> ExtractionConfig:
        """The paper's literal parameters (§3.1-3.4), tuned for its 697 mm scene.

        The paper's J thresholds are negative (J_t = -185.58, J_peak = -125); with our
        sign convention (-LoG is positive on bright blobs) they accept almost every pixel.
        """
        return ExtractionConfig(
            raw_threshold_abs=114.66,
            peak_abs=155.0,
            nlog_peak_abs=-125.0,
            nlog_floor_abs=-185.58,
            nlog_sigma_px=2.0,
            h_min_px=95,
            h_max_px=225,
            n_max=120 * 100,
            q_max=0.9,
        )


@dataclass(frozen=True)
class PersistenceConfig:
    """K frames of history, C_min frames of presence, and the motion gate (pixels)."""

    k_frames: int = 5
    c_min: int = 2
    motion_tolerance_px: float = 0.35

    def __post_init__(self) -> None:
        if self.k_frames < 1 or self.c_min < 1:
            raise ValueError("k_frames and c_min must be >= 1")

    @staticmethod
    def single_frame() -> PersistenceConfig:
        """Each frame on its own (K = C_min = 1): the honest setting for a moving target
        (docs/algorithm.md §3.4)."""
        return PersistenceConfig(k_frames=1, c_min=1)


@dataclass(frozen=True)
class MatchingConfig:
    """Deterministic annealing parameters.

    alpha_mm, alpha_per_m : distance tolerance alpha = alpha_mm + alpha_per_m * range_m.
    psi_start, psi_end : inverse temperature range in units of 1 / alpha^2.
    growth : c of Eq. 35 (psi_{m+1} = c psi_m).
    clip_factor : rho is clipped at clip_factor * alpha; with 1 (default) a pair supports
        an assignment by up to alpha^2 and an incompatible pair costs nothing, so the
        null label (energy 0) wins exactly when a blob has no support.
    size_weight : weight (in alpha^2 units) of the apparent-size unary term; 0 disables.
    residual_factor : rigid residual tolerance per pair is clip(4 sigma, alpha,
        residual_factor * alpha), sigma from the weights when given.
    min_matches : fewest matched reflectors for a pose.
    """

    alpha_mm: float = 12.0
    alpha_per_m: float = 3.0
    psi_start: float = 0.02
    psi_end: float = 50.0
    growth: float = 1.25
    clip_factor: float = 1.0
    size_weight: float = 0.5
    residual_factor: float = 2.5
    min_matches: int = 3

    def alpha_for(self, observed_mm: np.ndarray) -> float:
        """alpha (mm) at the median range of observed points (gamma, 3)."""
        y = np.asarray(observed_mm, float)
        rng_m = median_1d(np.sqrt((y * y).sum(axis=1))) / 1000 if len(y) else 0.0
        return self.alpha_mm + self.alpha_per_m * rng_m

    def pair_tolerance_mm(self, alpha_mm: float, weights: np.ndarray) -> np.ndarray:
        """Per-pair rigid residual tolerance clip(4 sigma, alpha, residual_factor alpha),
        sigma = 1 / sqrt(weight); shape (gamma,)."""
        sigma = 1.0 / np.sqrt(np.asarray(weights, float))
        return np.minimum(np.maximum(4.0 * sigma, alpha_mm), self.residual_factor * alpha_mm)


@dataclass(frozen=True)
class TrackingConfig:
    """enabled : use tracking after a confident pose. reacquire_every : a full acquisition
    pass at least every this many frames. margin_px : search margin around a reflector's
    predicted disc (inter-frame motion allowed). min_diameter_px : reflectors predicted
    smaller than this are not tracked (their windows hold too little to verify)."""

    enabled: bool = False
    reacquire_every: int = 15
    margin_px: float = 4.0
    min_diameter_px: float = 1.0

    def __post_init__(self) -> None:
        if self.reacquire_every < 1:
            raise ValueError(f"reacquire_every must be >= 1, got {self.reacquire_every}")
        if self.margin_px < 1:
            raise ValueError(f"margin_px must be >= 1, got {self.margin_px}")


@dataclass(frozen=True)
class PixelFitConfig:
    """The pixel-level pose fit after §5 (``tofpose.stages.pixelfit``): the pose refined
    on the matched markers' raw gray and distance pixels, its covariance the model's
    inverse Fisher information; the centroid pose stays when the fit falls back.

    enabled : run it on every ok pose (off by default, as the live loop runs: it costs
        tens of ms a frame, docs/results.md "Pixel-level fit against the bound";
        ``tofpose estimate`` and ``reprocess`` turn it on unless ``--no-pixel-fit``).
    fit_range_offset : also fit a range offset common to every marker (an uncalibrated
        camera).
    max_marker_rms_sigma : a marker whose pixels' residual RMS exceeds this many sigmas
        (a glint, an occluded disc) makes the fit fall back.
    max_shift_chi2 : the fit refines the centroid pose; a fitted pose further from it
        than this squared Mahalanobis distance under the centroid pose's own covariance
        (default chi^2 with 6 degrees of freedom at 99.73 %: 3 sigma) is another answer,
        not a refinement of the same one (a model the frame does not follow, such as a
        blurred lens, drawn to a wrong minimum): the centroid pose stays, and the reason
        says how far the fit went.
    """

    enabled: bool = False
    fit_range_offset: bool = False
    max_marker_rms_sigma: float = 3.0
    max_shift_chi2: float = 20.06

    def __post_init__(self) -> None:
        if not self.max_marker_rms_sigma > 0:
            raise ValueError(
                f"max_marker_rms_sigma must be positive, got {self.max_marker_rms_sigma}"
            )
        if not self.max_shift_chi2 > 0:
            raise ValueError(f"max_shift_chi2 must be positive, got {self.max_shift_chi2}")


Refinement = Literal["ml", "los", "none"]


@dataclass(frozen=True)
class FitSettingsFields:
    """The §5 fields ``SolveConfig`` and ``PipelineConfig`` share (declared once; their
    meaning is documented on ``PipelineConfig``)."""

    refinement: Refinement = "ml"
    correct_perspective_bias: bool = True
    mixed_pixel_radius_px: float = 4.0
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
    range_offset_mean_mm: float = 0.0
    focal_length_sigma_rel: float | None = None
    common_centroid_bias_px: float = 0.05
    class_centroid_bias_px: float = 0.02
    size_scaled_centroid_bias: bool = True
    outlier_sigma: float = 6.0
    outlier_chi2_per_dof: float = 4.0
    max_view_angle_deg: float = 80.0
    dark_check_max_matches: int = 3
    photometric_check: bool = True
    centroid_sigma_floor_px: float = 0.03
    range_sigma_floor_mm: float = 1.0
    los_tolerance: float = 0.002


@dataclass(frozen=True)
class SolveConfig(FitSettingsFields):
    """The §5 stage's settings (``solve.PoseSolver``, ``tracking_frame.CompiledTracker``):
    the pose fit, its refinement, outlier step, verification and reported covariance.
    The ``FitSettingsFields`` are ``PipelineConfig``'s fields of the same names,
    documented there; the pipeline composes it (``PipelineConfig.solve``), and
    ``min_matches`` and ``residual_factor`` are the matching stage's (``MatchingConfig``).
    """

    min_matches: int = 3
    residual_factor: float = 2.5


@dataclass(frozen=True)
class PipelineConfig(FitSettingsFields):
    """All pipeline parameters: the stages' records, and the §5 settings (declared in
    ``FitSettingsFields``, shared with ``SolveConfig``) as fields of its own.

    refinement : "ml" (ours: Gauss-Newton on bearings and ranges, the default), "los"
        (the paper's line-of-sight iteration, Eqs. 51-52), or "none" (SVD only).
    correct_perspective_bias : shift centroids by the predicted offset between the image
        ellipse's centre and the projected disc centre, then re-solve.
    mixed_pixel_radius_px : a matched marker whose disc appears smaller than this
        radius takes its range from the mixing model of its pixels and its surround
        (``stages.extraction.kernels.mixed_pixels``) instead of its pixels' median, which the
        surround
        pulls towards itself when few pixels are covered whole; 0: never (the paper's
        preset). 4 px: from there on most of a disc's pixels are covered whole.
    ellipse_confirmation : run §3.3 (confirm candidate shapes, split merged components).
    verify_pose : refuse a pose that makes the target face away from the camera (beyond
        ``max_view_angle_deg``) or that predicts a well-resolved reflector where the
        frame has no bright pixel (catches congruent-triangle mismatches with 3 markers).
    reject_outliers, outlier_sigma : after the fit, drop a matched reflector while one
        is more than ``outlier_sigma`` off and more than ``matching.min_matches`` remain,
        refitting each time (ours: a spurious blob or a merged pair next to a marker's
        position passes the matching tolerance but bends the pose by degrees). Below 5
        reflectors the largest whitened residual (lateral and range, in predicted
        sigmas) is tested; from 5, the reflector the fit without it predicts worst, in
        sigmas of that prediction (``kernels.pose.deleted_residual_norm``; never more
        than its whitened residual there, 0.77-0.92 of it on the paper target's eight
        markers, so a bent marker must be 10-30 % further off than before 2026-12 to go;
        6 stays far beyond the chi(3) tail of a good one: 7e-8 of them exceed it).
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
    range_offset_mean_mm : the mean of that offset's prior, mm (0: none known; ``tofpose
        estimate`` and ``reprocess`` learn it, with its sigma, over the recording,
        ``stages.pose.range_bias``): estimated about it, or taken out of the ranges as it
        is where the offset is not estimated.
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
    focal_length_sigma_rel : relative sigma of the focal length's calibration; None (the
        default): the camera's own (``CameraModel.focal_length_sigma_rel``: what its
        description states, 0 when it states none). A camera description gives the
        intrinsics its frames are to be measured with, so an unstated uncertainty is
        taken as none; 0.002 (0.2 %) is a checkerboard calibration's typical one. Until
        2026-12 this was a fixed 0.2 % for every camera: on frames rendered with exact
        intrinsics (ours and another renderer's) it made the reported z sigma ~0.2 % of
        the range (2 mm at 1 m) where the errors were a tenth of that.
    common_centroid_bias_px : sigma of a centroid error common to a frame's markers, for
        markers of at most ``stages.pose.solve.RIM_RADIUS_PX`` (2 px) image radius,
        whose pixels are mostly rim pixels (0.05 px: the common-mode error of the
        matched centroids measured over the physics robustness study's families,
        ``bench/physics.py``'s scale column, 3-8 m: 0.02-0.05 px in most cells; the
        'all' family at 8 m reads up to 0.066 px in some runs). Over the pattern's rms radius in
        the image it is a scale error, estimated with the range offset and reported in
        the covariance (``kernels.pose.class_scale_covariance``'s common term). Larger
        discs have a smaller share of rim pixels and a smaller common error: the sigma
        falls as the rim's width over the matched markers' median image radius
        (``solve.centroid_bias_factor``: the rim is ``RIM_RADIUS_PX`` widened by two of
        the frame's PSF sigmas, ``FrameStats.psf_sigma_px``; at 0.7-2 m on the
        simulator's families the measured common-mode error is 0.004-0.014 px with sharp
        optics, up to 0.03 px with a 1-1.5 px PSF). Until 2026-12 this sigma applied
        at every size and to each size class independently, which made the reported
        attitude and lateral sigmas 2-4x the errors at 0.7-2 m and on a 640 x 480 sensor.
    size_scaled_centroid_bias : the scaling above and the per-class split
        (``class_centroid_bias_px``); on by default since 2026-12-08. Off,
        ``common_centroid_bias_px`` enters the covariance per size class, unscaled, and
        the range offset's prior unscaled (the priors before 2026-12), which made the
        reported sigmas 2-4x the errors at 0.7-2 m. It was opt-in for one stop because
        the slewing turntable (2 m, a 5 deg / 4 s yaw sine) put 45 % of the poses
        beyond 3 sigma with it; the cause was the simulator's frame stamp (the first
        sub-frame's start, 1.5 sub-frame periods before the instant the four samples
        average about: ``sim.bench.SimulatedBench.subframe_poses``), not the covariance.
        Judged at the acquisition's middle, the same run gives NEES/6 1.38 and 4 %
        beyond 3 sigma with it (0.57 and 4 % without).
    class_centroid_bias_px : sigma of the part of that error one size class of markers
        shares apart from the others (their blobs mix with the surround, the PSF and the
        fall-off alike, by their size), with the same size factor; where the sizes sit
        on different sides of the pattern, the fit reads it as a tilt. 0.02 px: the
        measured per-class common-mode error beyond the common scale stays below 0.018
        px (random part included) in every family of the physics study at 0.7-8 m.
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
    photometric_check : refuse a pose whose matched reflectors differ by more than
        ``stages.pose.photometry.MAX_RADIANCE_RATIO`` (8x) in return per disc area
        (aperture photometry at their centroids, saturated and unmeasurably faint ones
        left out): one target's reflectors are one material under one incidence, and
        correct matches differ by at most 5x over every physics the project renders; a
        match that gives an 80 mm disc a speck of noise and a 35 mm disc the frame's
        brightest blob does not.
    centroid_sigma_floor_px, range_sigma_floor_mm : floors of the per-reflector
        measurement sigmas (``tofpose.stages.extraction.uncertainty``) used as weights and in the
        covariance.
    """

    extraction: ExtractionConfig = field(default_factory=ExtractionConfig)
    persistence: PersistenceConfig = field(default_factory=PersistenceConfig)
    matching: MatchingConfig = field(default_factory=MatchingConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    pixel_fit: PixelFitConfig = field(default_factory=PixelFitConfig)
    ellipse_confirmation: bool = True
    matcher: Literal["annealing", "ransac"] = "annealing"
    triplet_fallback: bool = True
    ransac_time_budget_ms: float | None = 5.0
    ransac_confidence: float | None = None
    ransac_seed: int = 0

    @property
    def solve(self) -> SolveConfig:
        """The §5 stage's own settings, composed from this configuration."""
        return SolveConfig(
            **{name: getattr(self, name) for name in _SOLVE_FIELDS},
            min_matches=self.matching.min_matches,
            residual_factor=self.matching.residual_factor,
        )

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
            class_centroid_bias_px=0.0,
        )


#: the §5 fields of ``PipelineConfig`` that make up its ``SolveConfig``
_SOLVE_FIELDS = tuple(f.name for f in fields(FitSettingsFields))


#: the frame the pixel- and count-valued defaults are tuned on: the EPC660's 320 x 240 at
#: count scale 1 (``CameraModel()``)
REFERENCE_FRAME_PIXELS = 320 * 240


def config_for_camera(
    config: PipelineConfig, *, width: int, height: int, count_scale: float
) -> PipelineConfig:
    """``config`` with the settings that are pixel counts or gray counts scaled from the
    EPC660's frame to another camera's (``CameraModel.width``, ``height``,
    ``count_scale``; docs/devices.md, "What the pipeline needs per camera").

    ``extraction.n_max`` (the active pixel cap) grows with the frame's pixel count: the
    paper's 120 x 100 is 16 % of a 320 x 240 frame but 3 % of an Azure Kinect's
    640 x 576, where the markers of a target at 0.5 m alone cover more. The gray-count
    thresholds (``min_contrast_counts``, and the paper preset's absolute ones) scale by
    the count scale. On the EPC660 (320 x 240, count scale 1) ``config`` comes back
    unchanged.
    """
    if width <= 0 or height <= 0 or not count_scale > 0:
        raise ValueError(
            f"camera size and count scale must be positive, got {width} x {height}, "
            f"count scale {count_scale}"
        )
    ex = config.extraction
    pixels = width * height
    if pixels == REFERENCE_FRAME_PIXELS and count_scale == 1.0:
        return config

    def counts(value: float | None) -> float | None:
        return None if value is None else value * count_scale

    return replace(
        config,
        extraction=replace(
            ex,
            n_max=max(1, round(ex.n_max * pixels / REFERENCE_FRAME_PIXELS)),
            min_contrast_counts=ex.min_contrast_counts * count_scale,
            raw_threshold_abs=counts(ex.raw_threshold_abs),
            peak_abs=counts(ex.peak_abs),
            nlog_peak_abs=counts(ex.nlog_peak_abs),
            nlog_floor_abs=counts(ex.nlog_floor_abs),
        ),
    )
