"""Pose from matched reflectors (§5) as the pipeline runs it: weighted SVD (Eqs. 40-50),
completion with unmatched blobs, perspective-bias correction, refinement (ML or the
paper's LOS, Eqs. 51-52), the outlier step, and verification against the frame.

``PoseSolver.solve`` takes the matched pairs and the frame's ``Measurements`` and returns
a ``Solution`` or ``Rejected``. The matched reflectors travel as one frozen
``MatchedObservations`` record (``without(i)`` drops one). Everything up to the
verification (SVD, completion, bias correction, the fit, the systematic range sigma and
the outlier loop) runs as one compiled call (``tofpose.stages.pose.kernels.solve``), the one the
tracking frame calls too.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
import scipy.stats

from tofpose.config import SolveConfig
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.geometry import RigidTransform
from tofpose.core.records import Candidates, FitSettings, camera_record, catalog_record
from tofpose.stages.extraction.constants import MIX_FIELDS
from tofpose.stages.extraction.extraction import Blob
from tofpose.stages.pose.arithmetic import COMPILED, PoseArithmetic
from tofpose.stages.pose.constants import (
    BEHIND_CAMERA,
    DARK_REFLECTOR,
    MIN_LEAVE_ONE_OUT,
    REFINE_LOS,
    REFINE_ML,
    REFINE_NONE,
)
from tofpose.stages.pose.photometry import MAX_RADIANCE_RATIO, aperture_returns, radiance_ratio
from tofpose.stages.pose.pose import STEP_SIGMA2, MLResult
from tofpose.stages.pose.records import (
    NO_OFFSET,
    CovarianceTerms,
    OutlierFit,
    PoseFit,
    RangeOffset,
    RangeOffsetPrior,
    Reflectors,
    SolvedPairs,
)

_REFINEMENT = {"none": REFINE_NONE, "ml": REFINE_ML, "los": REFINE_LOS}

if TYPE_CHECKING:
    from tofpose.calibration.range import RangeCorrection


@functools.cache
def chi2_limit(dof: int, p: float) -> float:
    """The p-quantile of chi^2 with ``dof`` degrees of freedom (SciPy)."""
    return float(scipy.stats.chi2.ppf(p, dof))


def focal_length_sigma_rel(config: SolveConfig, camera: CameraModel) -> float:
    """The focal length's relative sigma the fit assumes: ``config``'s when it sets one,
    else the camera's (``CameraModel.focal_length_sigma_rel``)."""
    if config.focal_length_sigma_rel is not None:
        return float(config.focal_length_sigma_rel)
    return float(camera.focal_length_sigma_rel)


#: a sharp disc's image radius (px) below which its pixels are mostly rim pixels
#: (covered in part, mixed with the surround, cut by the pixel grid): the centroid errors
#: common to a frame's markers (``common_centroid_bias_px``, ``class_centroid_bias_px``)
#: are their size there; a larger disc's rim is a fraction ~ RIM_RADIUS_PX / r of it,
#: and its common-mode error falls alike (``centroid_bias_factor``)
RIM_RADIUS_PX = 2.0
#: the lens blur widens the rim by this many PSF sigmas (the blurred edge's span on
#: either side): a blurred disc's brightness gradient (entrance-angle fall-off across a
#: tilted face) then moves every marker's centroid alike (0.05-0.1 px at 1-3 m with a
#: 1-1.5 px PSF on the simulator's families)
RIM_BLUR_SIGMAS = 2.0


def centroid_bias_factor(
    diameter_mm: np.ndarray, range_mm: np.ndarray, fx: float, psf_sigma_px: float = 0.0
) -> float:
    """The factor on the common centroid-error priors for markers of ``diameter_mm``
    (m,) at ``range_mm`` (m,) through a lens of PSF sigma ``psf_sigma_px``: min(1, rim /
    r), rim = ``RIM_RADIUS_PX`` + ``RIM_BLUR_SIGMAS`` psf_sigma_px, r the median of their
    image radii fx d / (2 range) px; 1 without markers or with a non-finite radius."""
    radii = sorted(
        (fx * np.asarray(diameter_mm, float) / (2.0 * np.asarray(range_mm, float))).tolist()
    )
    m = len(radii)
    if m == 0:
        return 1.0
    radius_px = radii[m // 2] if m % 2 else 0.5 * (radii[m // 2 - 1] + radii[m // 2])
    psf = float(psf_sigma_px) if math.isfinite(psf_sigma_px) and psf_sigma_px > 0 else 0.0
    rim_px = RIM_RADIUS_PX + RIM_BLUR_SIGMAS * psf
    if not math.isfinite(radius_px) or radius_px <= rim_px:
        return 1.0
    return rim_px / radius_px


def offset_prior(
    config: SolveConfig, sigma_mm: float, camera: CameraModel, bias_factor: float = 1.0
) -> RangeOffsetPrior:
    """The common range offset's prior for ``kernels.pose.common_range_offset``: sigma
    ``sigma_mm`` (the uncalibrated or calibrated range-bias sigma), and the image scale's
    uncertainty from the focal length's (``focal_length_sigma_rel``) and
    ``common_centroid_bias_px`` times ``bias_factor`` (``centroid_bias_factor``; over
    the camera's focal length)."""
    return RangeOffsetPrior(
        sigma_mm=float(sigma_mm),
        focal_length_sigma_rel=focal_length_sigma_rel(config, camera),
        centroid_bias_rad=float(config.common_centroid_bias_px) * bias_factor / camera.fx,
        mean_mm=float(config.range_offset_mean_mm),
    )


@dataclass(frozen=True)
class Measurements:
    """Candidate reflectors back-projected (Eqs. 7-8) with their sigmas.

    blobs : the n blobs, in order, where the stage that measured them built records
    (acquisition; a tracked frame measures its windows' pixel lists in one compiled call
    and gives none); area_px : (n,) their pixel counts; uv_px : (n, 2) centroids (Eq. 19);
    range_mm : (n,) ranges (Eq. 20); y_mm : (n, 3) points in the camera frame (Eq. 8);
    weights : (n,) the weights of Eq. 21, ``1 / (sigma_range^2 + (range sigma_px / f)^2)``;
    sigma_px, sigma_range_mm : (n,) per-reflector sigmas
    (``uncertainty.measurement_sigmas``); mixing : (n,
    ``stages.extraction.constants.MIX_FIELDS``)
    their mixing sums (NaN rows, or None: none).
    """

    blobs: tuple[Blob, ...]
    area_px: np.ndarray
    uv_px: np.ndarray
    range_mm: np.ndarray
    y_mm: np.ndarray
    weights: np.ndarray
    sigma_px: np.ndarray
    sigma_range_mm: np.ndarray
    mixing: np.ndarray | None = None

    def as_unmatched(self) -> list[tuple[float, float, float]]:
        """(u, v, range) of every candidate, for a result without a pose."""
        return [(u[0], u[1], r) for u, r in zip(self.uv_px, self.range_mm, strict=True)]


@dataclass(frozen=True)
class MatchedObservations:
    """The m matched reflectors as the solver uses them, row i for one reflector.

    k_idx, i_idx : (m,) observed (into ``Measurements``) and catalog indices;
    x_mm : (m, 3) catalog positions (target frame); uv_px : (m, 2) centroids after the
    perspective-bias correction; bearings : (m, 3) their unit lines of sight (Eq. 9);
    range_mm : (m,); y_mm : (m, 3) back-projected points (Eq. 8); sigma_bearing_rad,
    sigma_range_mm : (m,) the noise model's sigmas (before any systematic term).
    """

    k_idx: np.ndarray
    i_idx: np.ndarray
    x_mm: np.ndarray
    uv_px: np.ndarray
    bearings: np.ndarray
    range_mm: np.ndarray
    y_mm: np.ndarray
    sigma_bearing_rad: np.ndarray
    sigma_range_mm: np.ndarray

    def __len__(self) -> int:
        return len(self.k_idx)

    def without(self, i: int) -> MatchedObservations:
        """The same observations with row ``i`` dropped (the outlier step)."""
        return self.subset(np.arange(len(self)) != i)

    def subset(self, keep: np.ndarray) -> MatchedObservations:
        """The rows where the (m,) bool mask ``keep`` is true (itself when all are)."""
        if keep.all():
            return self
        return MatchedObservations(
            **{name: getattr(self, name)[keep] for name in self.__dataclass_fields__}
        )


@dataclass(frozen=True)
class Solution:
    """A solved pose (§5): ``T_camera_target`` maps target-frame points into the camera
    frame; ``observations`` are the reflectors it was solved from (outliers removed);
    iterations : refinement iterations; ml : the maximum-likelihood evaluation at the
    pose (covariance, chi^2, norms). ``T_svd`` : the weighted absolute orientation
    (Eqs. 40-50) of the same observations with the fit's weights, before any refinement:
    what §5.1 alone gives on them (``T_camera_target`` minus it is what refinement
    changed)."""

    T_camera_target: RigidTransform
    observations: MatchedObservations
    iterations: int
    ml: MLResult
    T_svd: RigidTransform | None = None


@dataclass(frozen=True)
class Rejected:
    """No pose: ``reason`` for the user; ``implausible`` when a pose was found but failed
    verification (the assignment may be a mirror image: worth the triplet fallback)."""

    reason: str
    implausible: bool = False


@dataclass(frozen=True)
class ThresholdedFrame:
    """A frame's active pixel set ``gray >= threshold`` (float32 comparison, as
    ``extraction.active_pixel_mask``), given as the frame and its I_t: ``verify``'s dark
    check reads a few small windows of it, and thresholding the whole frame each
    tracked frame cost more than the check itself. gray : (H, W) float32."""

    gray: np.ndarray
    threshold: float
    #: the frame's lens blur (``FrameStats.psf_sigma_px``), px: it sets the centroid
    #: errors' size prior (``centroid_bias_factor``)
    psf_sigma_px: float = 0.0


#: the frame ``verify`` passes when the dark check does not run (never read)
_NO_FRAME = ThresholdedFrame(np.zeros((1, 1), np.float32), 0.0)


def matched_observations(solved: SolvedPairs) -> MatchedObservations:
    """The reflectors ``kernels.solve.solve_pairs`` kept, as the solver reports them: the
    common range offset its fit estimated taken out of their ranges and points (y = rho e,
    Eq. 8), their sigmas the noise model's."""
    observed, offset = solved.observed, solved.result.offset_mm
    e = observed.e
    y = e * observed.rho[:, None]
    obs = MatchedObservations(
        k_idx=solved.k_idx,
        i_idx=solved.i_idx,
        x_mm=observed.x,
        uv_px=solved.uv,
        bearings=e,
        range_mm=observed.rho - offset,
        y_mm=y - e * offset,
        sigma_bearing_rad=observed.sb,
        sigma_range_mm=observed.sr,
    )
    return obs.subset(solved.result.kept)


def fitted_reflectors(obs: MatchedObservations, fit: PoseFit) -> Reflectors:
    """The reflectors ``obs`` with the sigmas their fit used (the frame's excess
    components included), as the covariance kernels take them."""
    c = np.ascontiguousarray
    return Reflectors(
        x=c(obs.x_mm), e=c(obs.bearings), rho=c(obs.range_mm), sr=c(fit.sr), sb=c(fit.sb)
    )


def fit_settings(config: SolveConfig) -> FitSettings:
    """The §5 settings as the compiled solve reads them (``kernels.solve.solve_pairs``,
    ``kernels.pose.fit_with_outliers``) from the stage's configuration, each under the
    configuration's name: the one place they are built, for the acquisition and the
    tracking paths alike."""
    return FitSettings(
        refinement=_REFINEMENT[config.refinement],
        los_tolerance=float(config.los_tolerance),
        step_sigma2=STEP_SIGMA2,
        correct_perspective_bias=bool(config.correct_perspective_bias),
        mixed_pixel_radius_px=float(config.mixed_pixel_radius_px),
        adapt_range_sigma=bool(config.adapt_range_sigma),
        max_systematic_range_sigma_mm=float(config.max_systematic_range_sigma_mm),
        max_systematic_centroid_sigma_px=float(config.max_systematic_centroid_sigma_px),
        reject_outliers=bool(config.reject_outliers),
        min_matches=int(config.min_matches),
        outlier_sigma=float(config.outlier_sigma),
        outlier_chi2_per_dof=float(config.outlier_chi2_per_dof),
    )


class PoseSolver:
    """§5 for one camera and catalog under the stage's ``SolveConfig``."""

    def __init__(
        self,
        camera: CameraModel,
        catalog: Catalog,
        config: SolveConfig,
        range_correction: RangeCorrection | None,
        *,
        arithmetic: PoseArithmetic = COMPILED,
    ) -> None:
        """``range_correction``: the camera's ranges are corrected with it; where the
        reflectors lie in its calibrated span the covariance takes the smaller common
        range-bias sigma (``calibrated_range_bias_sigma_mm``), elsewhere the uncalibrated
        one (the model is an extrapolation there). ``arithmetic``: the implementation of
        the fit, the covariances and the checks (``tofpose.arithmetic``)."""
        self.camera = camera
        self.arithmetic = arithmetic
        self.config = config
        self._xyz = np.ascontiguousarray(catalog.positions_mm, dtype=float)
        self._xyz_mean = self._xyz.mean(axis=0)
        self._cos_max_view = math.cos(math.radians(config.max_view_angle_deg))
        self._d = np.ascontiguousarray(catalog.diameters_mm, dtype=float)
        self._ids = catalog.ids
        self._correction = range_correction
        self._camera_record = camera_record(camera)
        self._catalog_record = catalog_record(catalog)
        self._fit_settings = fit_settings(config)
        # each reflector's diameter class (index among the catalog's distinct diameters)
        sizes, self._size_class = np.unique(np.round(self._d, 3), return_inverse=True)
        self._n_sizes = len(sizes)

    # ------------------------------------------------------------------------------------
    def solve(
        self,
        pairs: np.ndarray,
        meas: Measurements,
        alpha_mm: float,
        active: ThresholdedFrame | None,
        *,
        dark_check_all: bool = False,
    ) -> Solution | Rejected:
        """Pose from matched pairs (m, 2) of observed and catalog indices: weighted SVD
        (Eqs. 40-50), completion, perspective-bias correction, refinement, outlier step
        and verification (§5). ``active`` : the frame and its I_t (the active pixel set,
        read by the dark check), or None when the check cannot run.

        The fit (``kernels.pose.fit_with_outliers``) first uses the noise model's range
        sigmas; with ``adapt_range_sigma`` it adds the frame's excess range and bearing
        sigmas (``pose.systematic_sigmas``, capped at ``max_systematic_range_sigma_mm`` and
        ``max_systematic_centroid_sigma_px``) and fits again. A single bad point (a
        reflection matched in a marker's place) bends the fit so that every residual looks
        large while without it the others agree, so that estimate is the smallest over the
        fits that leave one reflector out (worst-fitting first: with one bad point the first
        such fit already gives 0). The outlier step then looks for a reflector to drop,
        re-estimating after each removal, when one is more than ``outlier_sigma`` off the
        fit (whitened norm) or the fit as a whole is inconsistent (chi^2 above
        ``outlier_chi2_per_dof`` per degree of freedom). A biased point with a small sigma
        drags the fit towards itself and hides, leaving good points with the large
        residuals (two markers imaged as one blob did so at 8 m, and the good ones were
        dropped); so from 5 reflectors on, each is predicted from a fit without it and the
        one predicted worst goes if it is off by more than ``outlier_sigma``; with 4 (a
        fit of 3 cannot single out the bad one of 4) the largest whitened residual goes.
        When completion added a blob and the outlier step then dropped matched ones, the
        fit without completion is taken if it keeps more reflectors."""
        cfg = self.config
        complete_mm = alpha_mm * cfg.residual_factor
        psf = 0.0 if active is None else active.psf_sigma_px
        solved = self._fit_pairs(pairs, meas, complete_mm, psf)
        kept = solved.result.kept
        n = len(pairs)
        if len(kept) > n and kept[n:].any() and not kept[:n].all():
            # completion added a blob and the outlier step then dropped matched ones: the
            # added blob may be what bent the fit (two markers imaged as one blob sits
            # near a predicted reflector); the fit without completion is taken when it
            # keeps more reflectors
            alone = self._fit_pairs(pairs, meas, 0.0, psf)
            if alone.result.kept.sum() > kept.sum():
                solved = alone
        return self.conclude(
            matched_observations(solved), solved.result, active, dark_check_all=dark_check_all
        )

    def _fit_pairs(
        self, pairs: np.ndarray, meas: Measurements, complete_mm: float, psf_sigma_px: float = 0.0
    ) -> SolvedPairs:
        """``kernels.solve.solve_pairs`` on matched pairs (m, 2) with completion within
        ``complete_mm`` (0: none)."""
        mixing = (
            meas.mixing
            if meas.mixing is not None
            else np.full((len(meas.range_mm), MIX_FIELDS), np.nan)
        )
        candidates = Candidates(
            uv_px=meas.uv_px,
            range_mm=meas.range_mm,
            y_mm=meas.y_mm,
            weights=meas.weights,
            sigma_px=meas.sigma_px,
            sigma_range_mm=meas.sigma_range_mm,
            mixing=mixing,
        )
        return self.arithmetic.solve_pairs(
            candidates,
            np.ascontiguousarray(pairs[:, 0]),
            np.ascontiguousarray(pairs[:, 1]),
            self._catalog_record,
            self._camera_record,
            self._fit_settings,
            float(complete_mm),
            self.offset_prior(meas.range_mm[pairs[:, 0]], pairs[:, 1], psf_sigma_px),
        )

    def offset_prior(
        self,
        range_mm: np.ndarray,
        catalog_index: np.ndarray | None = None,
        psf_sigma_px: float = 0.0,
    ) -> RangeOffsetPrior:
        """What the fit knows of the common range offset before the frame (the module's
        ``offset_prior``; ``NO_OFFSET`` unless ``estimate_range_offset``), for
        reflectors at ``range_mm`` (m,): the catalog's reflectors ``catalog_index`` (m,)
        when given (their image size and the lens blur ``psf_sigma_px`` set
        ``centroid_bias_factor``), else the full centroid-error prior."""
        if not self.config.estimate_range_offset:
            return NO_OFFSET
        factor = (
            1.0
            if catalog_index is None or not self.config.size_scaled_centroid_bias
            else self.bias_factor(range_mm, catalog_index, psf_sigma_px)
        )
        return offset_prior(self.config, self.range_bias_sigma_mm(range_mm), self.camera, factor)

    def bias_factor(
        self, range_mm: np.ndarray, catalog_index: np.ndarray, psf_sigma_px: float = 0.0
    ) -> float:
        """``centroid_bias_factor`` of the catalog's reflectors ``catalog_index`` (m,) at
        ``range_mm`` (m,) through a lens of PSF sigma ``psf_sigma_px``."""
        return centroid_bias_factor(
            self._d[np.asarray(catalog_index)], range_mm, self.camera.fx, psf_sigma_px
        )

    def conclude(
        self,
        obs: MatchedObservations,
        result: OutlierFit,
        active: ThresholdedFrame | None,
        *,
        dark_check_all: bool = False,
    ) -> Solution | Rejected:
        """The fitted pose of ``obs`` (the reflectors kept, the common range offset taken
        out: ``matched_observations``) from ``result`` (the fit with its outlier step;
        its ``fit``'s sigmas are the ones the fit used, the frame's excess components
        included): verified against the frame (``active`` : the frame, its I_t and its lens
        blur; its pixels are read by the dark check when few reflectors are matched,
        ``dark_check_max_matches``, and the photometric check; its blur sets the
        centroid-error priors' size factor, ``centroid_bias_factor``), refused
        when its residuals stay inconsistent with those sigmas (chi^2 beyond
        ``consistency_p``), with the covariance of the fit (6, 6; the pipeline scales it
        by the a-posteriori variance factor) and of the common range bias the data cannot
        reveal."""
        fit = result.fit
        R, t = fit.R, fit.t
        T = RigidTransform(R, t)
        ar = self.arithmetic
        if self.config.verify_pose:
            problem = self.verify(T, active, obs.i_idx, dark_check_all=dark_check_all)
            if not problem and self.config.photometric_check and active is not None:
                problem = self.photometric_problem(T, active, obs)
            if problem:
                return Rejected(f"pose rejected: {problem}", implausible=True)
        dof = 3 * len(obs.i_idx) - 6
        # chi^2 at the ML optimum only: an SVD or LOS pose's chi^2 is not minimised
        if self.config.consistency_p is not None and dof > 0 and self.config.refinement == "ml":
            limit = chi2_limit(dof, self.config.consistency_p)
            if not fit.chi2 <= limit:
                return Rejected(
                    self._inconsistent(obs, fit.norms, float(fit.chi2), dof, limit),
                    implausible=True,
                )
        # the common offset's uncertainty: its posterior sigma when the fit estimated it
        # (``obs`` then holds the ranges with the offset taken out), else the prior's
        bias = (
            result.offset_sigma_mm
            if result.offset_mm != 0
            else (self.range_bias_sigma_mm(obs.range_mm))
        )
        fitted = fitted_reflectors(obs, fit)
        cfg = self.config
        # the image scale's errors: one common scale (the focal length's and the centroid
        # error common to every marker, over the pattern's rms radius, as in the range
        # offset's prior) and one per size class, both for markers of this image size
        if cfg.size_scaled_centroid_bias:
            psf = 0.0 if active is None else active.psf_sigma_px
            factor = self.bias_factor(fitted.rho, obs.i_idx, psf)
            common_scale, _ = ar.pattern_scale_sigma(
                np.ascontiguousarray(fitted.e), offset_prior(cfg, 0.0, self.camera, factor)
            )
            class_bias_px = float(cfg.class_centroid_bias_px) * factor
        else:  # the priors as before 2026-12: the full common error per size class
            common_scale = focal_length_sigma_rel(cfg, self.camera)
            class_bias_px = float(cfg.common_centroid_bias_px)
        by_size = common_scale > 0 or class_bias_px > 0
        leave_one_out = cfg.leave_one_out_covariance and len(obs.i_idx) >= MIN_LEAVE_ONE_OUT
        terms = CovarianceTerms(
            bias_sigma_mm=float(bias),
            by_size=by_size,
            group=np.ascontiguousarray(self._size_class[obs.i_idx], dtype=np.int64),
            n_groups=self._n_sizes,
            bias_rad=class_bias_px / self.camera.fx,
            common_scale_sigma=float(common_scale),
            leave_one_out=bool(leave_one_out),
        )
        # one compiled call for the three (they share the Jacobian at the pose)
        reported = ar.concluding_covariances(fitted, R, t, terms)
        extra = reported.range_bias if bias > 0 else None
        if by_size:
            extra = reported.by_size if extra is None else extra + reported.by_size
        spread = reported.spread if leave_one_out else None
        ml = MLResult(
            R,
            t,
            fit.covariance,
            float(fit.chi2),
            int(fit.iterations),
            fit.norms,
            bias_covariance=extra,
            # the prior as the fit chose it: from the ranges as measured (``obs`` holds
            # them with the offset taken out)
            range_offset=RangeOffset(
                float(result.offset_mm),
                float(bias),
                self.range_bias_sigma_mm(obs.range_mm + result.offset_mm)
                if cfg.estimate_range_offset
                else 0.0,
                float(cfg.range_offset_mean_mm) if cfg.estimate_range_offset else 0.0,
            ),
            leave_one_out_covariance=spread,
        )
        c = np.ascontiguousarray
        # the fit's weights (as kernels.pose.fit_pose's)
        weights = 1.0 / (fit.sr**2 + (obs.range_mm * fit.sb) ** 2)
        T_svd = RigidTransform(*ar.absolute_orientation(c(obs.x_mm), c(obs.y_mm), c(weights)))
        return Solution(T, obs, int(fit.iterations), ml, T_svd=T_svd)

    def _inconsistent(self, obs, norms, chi2: float, dof: int, limit: float) -> str:
        """The reason for a pose whose residuals the measurement model cannot explain,
        naming the reflectors that fit worst (whitened residual norms)."""
        worst = np.argsort(-np.asarray(norms))[:3]
        named = ", ".join(f"{int(self._ids[obs.i_idx[j]])}: {norms[j]:.1f}" for j in worst)
        return (
            f"pose rejected: residuals inconsistent with the measurement model (chi^2 "
            f"{chi2:.1f} for {dof} degrees of freedom, limit {limit:.1f}; worst reflectors, "
            f"whitened residual: {named})"
        )

    def range_bias_sigma_mm(self, range_mm: np.ndarray) -> float:
        """Sigma of the common range offset for reflectors at ``range_mm`` (m,): the
        calibrated one when a range correction is applied and its calibrated span holds
        every reflector, the uncalibrated one otherwise."""
        cfg = self.config
        c = self._correction
        if c is not None and c.covers(float(range_mm.min())) and c.covers(float(range_mm.max())):
            return cfg.calibrated_range_bias_sigma_mm
        return cfg.range_bias_sigma_mm

    def photometric_problem(
        self, T: RigidTransform, active: ThresholdedFrame, obs: MatchedObservations
    ) -> str:
        """Why the matched reflectors' returns per disc area cannot be one target's
        (``photometry``), or '' when they can: ``active``'s frame read by aperture
        photometry at ``obs``' centroids, each disc's image radius predicted at the pose
        ``T``."""
        centres = self._xyz[obs.i_idx] @ T.R.T + T.t_mm
        radius_px = 0.5 * self.camera.fx * self._d[obs.i_idx] / np.maximum(centres[:, 2], 1e-6)
        returns = aperture_returns(
            self.arithmetic, active.gray, obs.uv_px, radius_px, self.camera.full_scale_counts
        )
        ratio, hi, lo = radiance_ratio(returns)
        if not ratio > MAX_RADIANCE_RATIO:
            return ""
        ids = self._ids[obs.i_idx]
        return (
            f"the matched reflectors' returns differ {ratio:.1f}x per disc area (reflector "
            f"{int(ids[hi])} against {int(ids[lo])}; one target's differ by less than "
            f"{MAX_RADIANCE_RATIO:g}x): a match of other light to the catalog"
        )

    # ------------------------------------------------------------------------------------
    def view_cosine(self, R: np.ndarray, t: np.ndarray) -> float:
        """Cosine between the target normal and the direction to the camera
        (``stages.matching.kernels.triplets.facing_cosine``)."""
        return self.arithmetic.facing_cosine(
            np.ascontiguousarray(R, dtype=float),
            np.ascontiguousarray(t, dtype=float),
            self._xyz_mean,
        )

    @property
    def facing(self) -> tuple[np.ndarray, float]:
        """The facing constraint as ``matching.match_by_triplets`` takes it: the catalog's
        centroid (3,) and the least cosine of the view angle."""
        return self._xyz_mean, self._cos_max_view

    def verify(
        self,
        T: RigidTransform,
        active: ThresholdedFrame | None,
        matched: np.ndarray,
        *,
        dark_check_all: bool = False,
    ) -> str:
        """Physical consistency of a pose with the frame; empty string when consistent:
        the target faces the camera within ``max_view_angle_deg``, every reflector is in
        front of it, and (at most ``dark_check_max_matches`` reflectors matched) no
        reflector that should be clearly visible falls on a dark part of the frame
        (``kernels.verify.pose_check`` states the rule). ``active`` : the frame and its
        I_t; read only for the dark check, and may be None otherwise. ``matched`` :
        (m,) int, the catalog indices of the matched reflectors, each once.
        ``dark_check_all``: the dark check whatever the number matched (a pose from
        hypotheses over every blob, which clutter can also satisfy)."""
        R, t = T.R, T.t_mm
        cos_view = self.view_cosine(R, t)
        if cos_view < self._cos_max_view:
            return (
                f"the target would face away from the camera (view angle "
                f"{np.degrees(np.arccos(np.clip(cos_view, -1, 1))):.0f} deg)"
            )
        dark_check = dark_check_all or len(matched) <= self.config.dark_check_max_matches
        is_matched = np.zeros(len(self._xyz), bool)
        is_matched[matched] = True
        frame = _NO_FRAME
        if dark_check:
            if active is None:
                raise ValueError("the dark check reads the frame: pass its ThresholdedFrame")
            frame = active
        outcome, i, u, v = self.arithmetic.pose_check(
            self._catalog_record,
            is_matched,
            np.ascontiguousarray(R, dtype=float),
            np.ascontiguousarray(t, dtype=float),
            self._camera_record,
            frame.gray,
            float(frame.threshold),
            dark_check,
        )
        if outcome == BEHIND_CAMERA:
            return "reflectors would be behind the camera"
        if outcome == DARK_REFLECTOR:
            return (
                f"reflector {int(self._ids[i])} should be visible at "
                f"({u:.0f}, {v:.0f}) px but the frame is dark there"
            )
        return ""
