"""The pixel-level pose fit: Levenberg-Marquardt over the pose and the discs' nuisance
parameters on the gray and distance pixels around the matched reflectors (``model.py``
for the forward model; the package docstring for what this adds to the paper's §5).

Parameters, in order: a small rotation ``w`` (rad, left-multiplied: ``R' = exp([w]) R``),
the translation step (mm), per disc its gain and its surround's level (counts), and
optionally one range offset common to all pixels (mm). The pose's order and
parametrisation are those of ``bench/crlb.py`` and of ``PoseResult.covariance``, so the
covariance blocks compare with the Cramer-Rao bound.

Noise (the sensor's own, not fitted): a gray pixel's variance is its shot noise, the
model's gray plus the ambient's share the gray does not show (``gray_extra_var``; by
default measured on the surround: its variance minus its level) plus quantisation; a
distance pixel's sigma is ``range_k_mm * sqrt(A + B) / A`` (CW-ToF, Lange 2000) with A the
model's mixed amplitude and ``A + B`` the gray's variance. Residuals are whitened by
these sigmas, re-evaluated at each iteration from the current model (a measured
``range_k_mm`` only over a solve's first ``NOISE_FREEZE_ITERATIONS``: ``constants``).

Saturated pixels (gray at full scale) are censored: the measurement says "at least full
scale", so a model at or above it leaves no residual and a model below it is pulled up
by ``(full scale - model) / sigma``; their distance (NaN) is not used. A disc whose
core is clipped (``MAX_CLIPPED_CORE_SHARE``) makes the fit fall back: its gain is then
seen only on the rim's outer pixels and the rim's model error moves the pose far beyond
its covariance (``constants.MAX_CLIPPED_CORE_SHARE`` has the numbers).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from scipy import ndimage
from scipy.spatial.transform import Rotation

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import Catalog
from tofpose.core.tof import SPEED_OF_LIGHT_MM_S
from tofpose.stages.pixelfit.constants import (
    CROWDED_GAP_MM,
    DAMPING_DOWN,
    DAMPING_UP,
    DISTANCE_MIN_COVERAGE,
    FULL_SCALE_COUNTS,
    GLINT_MAX_SHARE,
    GLINT_PEAK_SIGMA,
    GLINT_TAIL_SIGMA,
    INITIAL_DAMPING,
    MAD_TO_SIGMA,
    MAX_CLIPPED_CORE_SHARE,
    MAX_ITERATIONS,
    MAX_MARKER_RMS_SIGMA,
    MIN_BEYOND_PIXELS,
    MIN_CONTRAST_SIGMA,
    MIN_DISC_DISTANCE_PIXELS,
    MIN_DISC_RIM_PIXELS,
    MIN_MARKERS,
    MIN_PLATE_PIXELS,
    MIN_RIM_PIXELS,
    NOISE_FREEZE_ITERATIONS,
    QUANTISATION_VAR,
    RELATIVE_RMS_FACTOR,
    RELATIVE_RMS_MIN_SIGMA,
    RIM_COVERAGE_EPS,
    ROTATION_STEP_RAD,
    START_STEP_TOLERANCE_SIGMA2,
    STEP_TOLERANCE_SIGMA2,
    SUBSAMPLES,
    TRANSLATION_STEP_MM,
    WINDOW_PAD_PX,
)
from tofpose.stages.pixelfit.kernels import normal as normal_kernel
from tofpose.stages.pixelfit.model import (
    GAIN_TERMS,
    DiscImageDerivatives,
    DiscImages,
    Discs,
    Prediction,
    Windows,
    build_windows,
    disc_images,
    disc_images_with_derivatives,
    gain_basis,
    pixel_gains,
    predict,
    predicted_rims,
)
from tofpose.stages.pixelfit.records import (
    FitConstants,
    FitRecord,
    ImageRecord,
    NuisanceRecord,
)
from tofpose.stages.pose.solve import chi2_limit

#: the simulator's and the paper's camera default, Hz (c / (2 f) = 24.98 m)
DEFAULT_MODULATION_HZ = 6.0e6
#: damping increases tried before an iteration gives up
MAX_DAMPING_TRIES = 12
#: discs smaller than this (radius, px) get one gain, larger ones a gain and its slopes
#: over the image (a few per cent across an 80 mm disc: the incidence fall-off), from
#: the second radius on its curvatures too (the fall-off is a dome over a large disc)
GAIN_SLOPE_MIN_RADIUS_PX = 4.0
GAIN_CURVE_MIN_RADIUS_PX = 8.0
G = GAIN_TERMS
#: ``disc_deletion``: a disc whose deletion moves the pose beyond this quantile of the
#: move's chi-square under the model is biased beyond its noise (0.99: one disc in a
#: hundred of a frame the model fits adds its move, a few per cent of the covariance);
#: directions of a move's covariance below ``DISC_DELETION_RANK_TOL`` of its largest are
#: not tested (the deletion does not move the pose there); below
#: ``MIN_DELETION_DISCS`` deletable discs (a pose left to fit without each) none is done
DISC_INFLUENCE_P = 0.99
DISC_DELETION_RANK_TOL = 1e-9
MIN_DELETION_DISCS = 4
#: least summed coverage a disc needs in its window, px (less: it is not in the image)
MIN_DISC_AREA_PX = 0.5


@dataclass(frozen=True)
class PixelNoise:
    """The sensor's noise model as the fit whitens its residuals with it.

    modulation_frequency_hz : float
        Sets ``mm_per_radian = c / (4 pi f)`` (phasor mixing) and the unambiguous range.
    range_k_mm : float or None
        ``sigma_d = range_k_mm * sqrt(A + B) / A`` per pixel (the simulator's
        ``mm_per_radian / demod_gain``; the pipeline pools it per frame). None: measured
        on the frame's distance residuals at each of a solve's first
        ``NOISE_FREEZE_ITERATIONS`` iterations, then held for the rest of it.
    gray_extra_var : float or None
        Gray variance beyond the model's level, counts^2 (the ambient B that background
        suppression removes from the gray but not from its noise). None: measured on the
        surround pixels (their variance minus their level).
    full_scale_counts : float
        Gray at or above it is saturated (censored).
    coverage_sigma : float or None
        The rim's model error: sigma of a partly covered pixel's coverage beyond what the
        exact-area model predicts (a pixel's response is not uniform over its area,
        a renderer samples it at points, the rim is not a perfect circle), as a fraction
        of the pixel. A rim pixel's gray then has the extra variance ``(coverage_sigma *
        dgray/dcoverage)^2`` and its distance ``(coverage_sigma * ddistance/dcoverage)^2``.
        None: measured on the frame's rim pixels after a first fit (their residuals'
        excess over the shot noise), 0 when they show none.
    disc_range_sigma_mm : float or None
        Sigma of a range error of each disc's own (the same on all its pixels,
        independent between discs: an uncalibrated camera's amplitude-related and
        per-pixel errors), mm; fitted as one nuisance parameter per disc with this prior.
        None: measured after a first fit on the spread of the discs' mean distance
        residuals, 0 when they show none.
    """

    modulation_frequency_hz: float = DEFAULT_MODULATION_HZ
    range_k_mm: float | None = None
    gray_extra_var: float | None = None
    full_scale_counts: float = FULL_SCALE_COUNTS
    coverage_sigma: float | None = None
    disc_range_sigma_mm: float | None = None

    def __post_init__(self) -> None:
        if not self.modulation_frequency_hz > 0:
            raise ValueError(
                f"modulation_frequency_hz must be positive, got {self.modulation_frequency_hz}"
            )
        if self.range_k_mm is not None and not self.range_k_mm > 0:
            raise ValueError(f"range_k_mm must be positive or None, got {self.range_k_mm}")
        if self.gray_extra_var is not None and not self.gray_extra_var >= 0:
            raise ValueError(f"gray_extra_var must be >= 0 or None, got {self.gray_extra_var}")
        if self.coverage_sigma is not None and not 0 <= self.coverage_sigma < 1:
            raise ValueError(f"coverage_sigma must be in [0, 1) or None, got {self.coverage_sigma}")
        if self.disc_range_sigma_mm is not None and not self.disc_range_sigma_mm >= 0:
            raise ValueError(
                f"disc_range_sigma_mm must be >= 0 or None, got {self.disc_range_sigma_mm}"
            )

    @property
    def mm_per_radian(self) -> float:
        """c / (4 pi f): distance per radian of phase, mm."""
        return SPEED_OF_LIGHT_MM_S / (4.0 * np.pi * self.modulation_frequency_hz)

    @property
    def unambiguous_range_mm(self) -> float:
        return SPEED_OF_LIGHT_MM_S / (2.0 * self.modulation_frequency_hz)

    @staticmethod
    def from_sensor(sensor) -> PixelNoise:
        """The noise of a sensor record with ``modulation_frequency_hz``,
        ``mm_per_radian`` and ``demod_gain`` (``tofpose.sim.render.SensorModel``); the
        gray's extra variance is still measured on the frame."""
        return PixelNoise(
            modulation_frequency_hz=float(sensor.modulation_frequency_hz),
            range_k_mm=float(sensor.mm_per_radian / sensor.demod_gain),
        )


@dataclass(frozen=True)
class PixelFitResult:
    """Outcome of ``fit_pose_to_pixels``.

    ok : bool
        The fit converged and every disc agrees with the model: use ``R``, ``t_mm`` and
        ``covariance``. False: keep the centroid pose; ``reason`` says why.
    reason : str
        Empty when ok.
    R : ndarray of shape (3, 3); t_mm : ndarray of shape (3,)
        The fitted pose (the starting pose when the fit could not start).
    covariance : ndarray of shape (6, 6) or None
        Over (rotation vector, rad, left-multiplied; translation, mm): the inverse Fisher
        information at the solution, nuisance parameters marginalised, times
        ``deletion_variance_factor``, plus the moves of the ``influential`` discs
        (``disc_deletion``).
    catalog_ids : ndarray of shape (K,); marker_rms_sigma : ndarray of shape (K,)
        Each disc's residual RMS in sigmas (gray and distance pixels it owns).
    gains : ndarray of shape (K, GAIN_TERMS)
        Fitted gain of a fully covered pixel, counts, over ``model.gain_basis`` (at the
        disc's predicted centre, then its slopes and curvatures over the disc; 0 for
        the terms of discs too small to measure them).
    levels : ndarray of shape (K,)
        Fitted surround level, counts.
    range_offset_mm, range_offset_sigma_mm : float
        Fitted common range offset and its posterior sigma (the other parameters
        marginalised), mm (0 unless fitted).
    iterations : int; converged : bool
    n_gray_pixels, n_distance_pixels, n_saturated : int
        Pixels in the gray residuals, in the distance residuals, and censored.
    n_glint_pixels : int
        Window pixels left out as bright spots in the surround (``_glint_pixels``).
    clipped_share : ndarray of shape (K,)
        Each disc's share of its fully covered pixels (at the fitted pose) that are
        saturated: 1 when its core is clipped (``_clipped_share``), NaN when it covers
        no pixel wholly.
    range_k_mm, gray_extra_var, coverage_sigma, disc_range_sigma_mm : float
        The noise model used (given or measured; coverage_sigma: the discs' median).
    influential : ndarray of shape (K,) bool; deletion_variance_factor : float
        The discs whose deletion moves the pose beyond what the model expects of it
        (their moves are in ``covariance``), and the other discs' variance factor
        (``disc_deletion``; 1 when not computed).
    left_out : ndarray of shape (L,) int; left_out_reason : str
        Matched markers the fit left out, in the order it left them out
        (``fit_pose_to_pixels``: their pixels unexplained or the disc dark, ``_blamed``)
        and, per disc, the rule that named it with the failed fit's reason; empty when
        none was.
    deletion_checked : bool
        Whether ``disc_deletion`` checked the covariance: False with fewer than
        ``MIN_DELETION_DISCS`` discs whose deletion leaves the pose determined (three
        matched markers), a singular information or ``disc_deletion_terms`` off, where
        ``covariance`` is the Fisher one alone and errs narrow
        (on the other renderer's far frames fitted on three of their markers: NEES/6
        2.2, 20 % beyond 3 sigma, against 1.3 and 1-4 % with four or more; the
        pipeline then widens it to the centroid pose's, ``PosePipeline``).
    """

    ok: bool
    reason: str
    R: np.ndarray
    t_mm: np.ndarray
    covariance: np.ndarray | None = None
    catalog_ids: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    marker_rms_sigma: np.ndarray = field(default_factory=lambda: np.zeros(0))
    gains: np.ndarray = field(default_factory=lambda: np.zeros((0, G)))
    levels: np.ndarray = field(default_factory=lambda: np.zeros(0))
    range_offset_mm: float = 0.0
    range_offset_sigma_mm: float = 0.0
    iterations: int = 0
    converged: bool = False
    n_gray_pixels: int = 0
    n_distance_pixels: int = 0
    n_saturated: int = 0
    n_glint_pixels: int = 0
    clipped_share: np.ndarray = field(default_factory=lambda: np.zeros(0))
    range_k_mm: float = float("nan")
    gray_extra_var: float = float("nan")
    coverage_sigma: float = 0.0
    disc_range_sigma_mm: float = 0.0
    influential: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))
    deletion_variance_factor: float = 1.0
    deletion_checked: bool = False
    left_out: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    left_out_reason: str = ""


@dataclass(frozen=True)
class _State:
    R: np.ndarray
    t_mm: np.ndarray
    gains: np.ndarray
    levels: np.ndarray
    offset_mm: float
    disc_offsets_mm: np.ndarray  # (K,) each disc's own range error (0: not fitted)

    def stepped(self, delta: np.ndarray, layout: _Layout) -> _State:
        """The state moved by ``delta`` (all parameters, ``_Problem.n_params``)."""
        k = layout.k
        return _State(
            R=Rotation.from_rotvec(delta[:3]).as_matrix() @ self.R,
            t_mm=self.t_mm + delta[3:6],
            gains=self.gains + delta[6 : 6 + G * k].reshape(k, G),
            levels=self.levels + delta[6 + G * k : 6 + (G + 1) * k],
            offset_mm=self.offset_mm
            + (float(delta[layout.offset_col]) if layout.offset_col >= 0 else 0.0),
            disc_offsets_mm=self.disc_offsets_mm
            + (delta[layout.disc_cols] if layout.disc_cols.size else 0.0),
        )


@dataclass(frozen=True)
class _Layout:
    """Where the parameters sit: the pose (6), per disc its gain terms (K x GAIN_TERMS)
    and its surround level (K), then the common range offset (``offset_col``, -1 when
    not fitted), then each disc's own range error (``disc_cols``, empty when not
    fitted)."""

    k: int
    fit_offset: bool
    fit_disc_offsets: bool

    @property
    def offset_col(self) -> int:
        return 6 + (G + 1) * self.k if self.fit_offset else -1

    @property
    def disc_cols(self) -> np.ndarray:
        if not self.fit_disc_offsets:
            return np.zeros(0, int)
        return 6 + (G + 1) * self.k + int(self.fit_offset) + np.arange(self.k)

    @property
    def n_params(self) -> int:
        discs = self.k if self.fit_disc_offsets else 0
        return 6 + (G + 1) * self.k + int(self.fit_offset) + discs


@dataclass(frozen=True)
class _Problem:
    """What stays fixed over the fit: the pixels, their roles and the model's constants."""

    discs: Discs
    win: Windows
    gray_rows: np.ndarray  # indices of unsaturated pixels
    sat_rows: np.ndarray  # indices of saturated pixels
    dist_rows: np.ndarray  # indices of pixels whose distance is fitted
    noise: PixelNoise
    reference_mm: float
    fit_offset: bool
    offset_sigma_mm: float  # the offset's prior sigma (inf: free)
    basis: np.ndarray  # (K, P, GAIN_TERMS) the discs' gain basis at the pixels
    free: np.ndarray  # (n_params,) bool: the parameters fitted (the rest stay at 0 step)
    # (P,) the part of each pixel the plate fills, and the surround's level beyond the
    # plate times the rest (counts): ``pixel_levels``
    plate_fraction: np.ndarray
    beyond_counts: np.ndarray
    disc_range_sigma_mm: float = 0.0  # each disc's own range error's prior (0: none)
    offset_mean_mm: float = 0.0  # the offset's prior mean (where it starts)
    compiled: bool = True  # the model's compiled kernel, else its NumPy reference
    near_flat: tuple[np.ndarray, np.ndarray] | None = None  # win.near_flat, kept
    numeric_jacobian: bool = False  # the pose's columns by central differences

    @property
    def layout(self) -> _Layout:
        return _Layout(len(self.discs.ids), self.fit_offset, self.disc_range_sigma_mm > 0)

    @property
    def n_params(self) -> int:
        return self.layout.n_params

    @property
    def _model_options(self) -> dict:
        """The keyword arguments both image calls of the model take from the problem."""
        return {
            "mm_per_radian": self.noise.mm_per_radian,
            "reference_mm": self.reference_mm,
            "compiled": self.compiled,
            "near_flat": self.near_flat,
        }

    def images(self, R: np.ndarray, t_mm: np.ndarray) -> DiscImages:
        return disc_images(R, t_mm, self.discs, self.win, **self._model_options)

    def pixel_levels(self, levels: np.ndarray) -> np.ndarray:
        """The surround's level at each pixel (P,), counts: its disc's plate level
        ``levels`` (K,) where the plate fills it, the beyond's (held, measured on the
        frame: ``_plate_surround``) where it does not."""
        return levels[self.win.owner] * self.plate_fraction + self.beyond_counts

    @cached_property
    def gray_pixels(self) -> np.ndarray:
        """The gray residuals' pixels: the unsaturated ones, then the censored ones."""
        return np.concatenate([self.gray_rows, self.sat_rows])

    @cached_property
    def row_basis(self) -> tuple[np.ndarray, np.ndarray]:
        """The gain basis (K, rows, GAIN_TERMS) at the gray residuals' pixels and at the
        distance residuals' (the Jacobian's gain columns; kept over the iterations)."""
        return self.basis[:, self.gray_pixels], self.basis[:, self.dist_rows]

    def images_with_derivatives(
        self, R: np.ndarray, t_mm: np.ndarray
    ) -> tuple[DiscImages, DiscImageDerivatives]:
        return disc_images_with_derivatives(R, t_mm, self.discs, self.win, **self._model_options)

    def predict(self, images: DiscImages, s: _State) -> Prediction:
        return predict(
            images,
            self.pixel_levels(s.levels),
            s.gains,
            mm_per_radian=self.noise.mm_per_radian,
            basis=self.basis,
            reference_mm=self.reference_mm,
            range_offset_mm=s.offset_mm + s.disc_offsets_mm[self.win.owner],
        )


@dataclass(frozen=True)
class _Sigmas:
    gray: np.ndarray  # (P,) counts
    distance_mm: np.ndarray  # (P,) mm
    range_k_mm: float


def _wrap(x: np.ndarray, period: float) -> np.ndarray:
    return (x + period / 2) % period - period / 2


def _gray_variance(pred: Prediction, extra_var: float) -> np.ndarray:
    return np.maximum(pred.gray, 0.0) + extra_var + QUANTISATION_VAR


@dataclass(frozen=True)
class _RimSensitivity:
    """How a rim pixel's model moves with each disc's coverage: ``gray2_k`` = (d gray /
    d c_k)^2, counts^2, and ``distance2_k`` = (d distance / d c_k)^2, mm^2 (both (K, P);
    0 where disc k covers the pixel wholly or not at all); ``gray2`` and ``distance2``
    (P,) their sums over the discs."""

    gray2_k: np.ndarray
    distance2_k: np.ndarray

    @property
    def gray2(self) -> np.ndarray:
        return self.gray2_k.sum(axis=0)

    @property
    def distance2(self) -> np.ndarray:
        return self.distance2_k.sum(axis=0)


def _rim_sensitivity(
    pb: _Problem, images: DiscImages, pred: Prediction, s: _State
) -> _RimSensitivity:
    """d gray / d c_k = gain_k - level; d mixed / d c_k = gain_k u_k - level plate, with
    u_k the disc's unit phasor at the pixel, and d distance = mm_per_radian Im(d mixed /
    mixed) (``model.predict``)."""
    cov = images.coverage  # (K, P)
    partial = (cov > RIM_COVERAGE_EPS) & (cov < 1.0 - RIM_COVERAGE_EPS)
    g = pixel_gains(s.gains, pb.basis)  # (K, P)
    level = pb.pixel_levels(s.levels)  # (P,)
    d_gray = np.where(partial, g - level, 0.0)
    unit = images.phasor / np.where(cov > 0, cov, 1.0)
    mixed = np.where(np.abs(pred.phasor) > 0, pred.phasor, 1.0)
    d_mixed = g * unit - level * images.plate_phasor
    d_dist = np.where(partial, pb.noise.mm_per_radian * np.imag(d_mixed / mixed), 0.0)
    return _RimSensitivity(gray2_k=d_gray**2, distance2_k=d_dist**2)


def _measured_coverage_sigma(
    pb: _Problem, pred: Prediction, sig: _Sigmas, rim: _RimSensitivity, crowded: np.ndarray
) -> np.ndarray:
    """The rim's model error per disc (K,) (``PixelNoise.coverage_sigma``) measured on
    the fitted frame. Per disc: its unsaturated rim pixels' squared gray residuals beyond
    their shot noise, over their summed squared sensitivity. The frame's value is the
    median over the discs, and every disc gets it, so that one disc the model does not
    explain (a glint on its rim) neither widens the others' sigmas nor hides from the
    per-disc residual check; a ``crowded`` disc (K,) bool, whose rim a neighbour may
    hide, gets its own when that is larger. All 0 unless the rims' excess as a whole is
    beyond twice the chi-square's own scatter."""
    k_count = len(pb.discs.ids)
    none = np.zeros(k_count)
    gray2 = rim.gray2
    rows = pb.gray_rows[gray2[pb.gray_rows] > 0]
    if len(rows) < MIN_RIM_PIXELS:
        return none
    r2 = (pb.win.gray[rows] - pred.gray[rows]) ** 2
    var = sig.gray[rows] ** 2
    if np.sum(r2 / var) <= len(rows) + 2.0 * np.sqrt(2.0 * len(rows)):
        return none
    owner = pb.win.owner[rows]
    own = np.full(k_count, np.nan)
    for k in range(k_count):
        mine = owner == k
        if mine.sum() >= MIN_DISC_RIM_PIXELS:
            own[k] = np.sum(r2[mine] - var[mine]) / np.sum(gray2[rows][mine])
    if np.sum(np.isfinite(own)) >= MIN_MARKERS:
        typical = float(np.nanmedian(own))
    else:
        typical = float(np.sum(r2 - var) / np.sum(gray2[rows]))
    excess = np.full(k_count, typical)
    larger = crowded & np.isfinite(own) & (own > typical)
    excess[larger] = own[larger]
    return np.sqrt(np.maximum(excess, 0.0))


def _measured_disc_range_sigma(pb: _Problem, pred: Prediction, sig: _Sigmas) -> float:
    """Each disc's own range error (``PixelNoise.disc_range_sigma_mm``) measured on the
    fitted frame: the spread of the discs' weighted mean distance residuals beyond their
    standard errors; 0 unless their chi-square exceeds its own scatter twice over (an
    uncalibrated camera's amplitude-related and per-pixel range errors differ from
    disc to disc; a calibrated one leaves none)."""
    j = pb.dist_rows
    dd = _wrap(pb.win.distance_mm[j] - pred.distance_mm[j], pb.noise.unambiguous_range_mm)
    w = 1.0 / sig.distance_mm[j] ** 2
    owner = pb.win.owner[j]
    means, var = [], []
    for k in range(len(pb.discs.ids)):
        mine = owner == k
        if mine.sum() >= MIN_DISC_DISTANCE_PIXELS:
            means.append(np.sum(w[mine] * dd[mine]) / np.sum(w[mine]))
            var.append(1.0 / np.sum(w[mine]))
    n = len(means)
    if n < MIN_MARKERS:
        return 0.0
    m, v = np.asarray(means), np.asarray(var)
    if np.sum(m**2 / v) <= n + 2.0 * np.sqrt(2.0 * n):
        return 0.0
    excess = float(np.mean(m**2 - v))
    return float(np.sqrt(excess)) if excess > 0 else 0.0


def _sigmas(
    pb: _Problem,
    pred: Prediction,
    extra_var: float,
    rim: _RimSensitivity | None = None,
    coverage_sigma: np.ndarray | None = None,
) -> _Sigmas:
    """Per-pixel sigmas at the current model (module docstring), with the rim's model
    error when ``coverage_sigma`` > 0; the range constant measured on the distance
    residuals when the noise model leaves it open."""
    var = _gray_variance(pred, extra_var)
    amp = np.maximum(np.abs(pred.phasor), 1e-6)
    shape = np.sqrt(var) / amp  # sigma_d / k
    edge_var_gray = edge_var_distance = None
    if rim is not None and coverage_sigma is not None and np.any(coverage_sigma > 0):
        edge_var_gray = np.einsum("k,kp->p", coverage_sigma**2, rim.gray2_k)
        edge_var_distance = np.einsum("k,kp->p", coverage_sigma**2, rim.distance2_k)
        var = var + edge_var_gray
    k = pb.noise.range_k_mm
    if k is None:
        j = pb.dist_rows
        if len(j) >= 3:
            z = _wrap(pb.win.distance_mm[j] - pred.distance_mm[j], pb.noise.unambiguous_range_mm)
            z = z / shape[j]
            k = float(MAD_TO_SIGMA * np.median(np.abs(z - np.median(z))))
        k = k if k and np.isfinite(k) and k > 0 else 1.0
    sigma_d = k * shape
    if edge_var_distance is not None:
        sigma_d = np.sqrt(sigma_d**2 + edge_var_distance)
    return _Sigmas(gray=np.sqrt(var), distance_mm=sigma_d, range_k_mm=float(k))


def _n_prior_rows(pb: _Problem) -> int:
    """Rows of ``_prior_residual``."""
    common = pb.fit_offset and np.isfinite(pb.offset_sigma_mm)
    return int(common) + (len(pb.discs.ids) if pb.disc_range_sigma_mm > 0 else 0)


def _prior_residual(pb: _Problem, s: _State) -> np.ndarray:
    """The range offset's prior as a residual row ((1,) when it has a finite prior, else
    (0,))."""
    rows = []
    if pb.fit_offset and np.isfinite(pb.offset_sigma_mm):
        rows.append(np.array([-(s.offset_mm - pb.offset_mean_mm) / pb.offset_sigma_mm]))
    if pb.disc_range_sigma_mm > 0:
        rows.append(-s.disc_offsets_mm / pb.disc_range_sigma_mm)
    return np.concatenate(rows) if rows else np.zeros(0)


def _residuals(pb: _Problem, pred: Prediction, sig: _Sigmas, s: _State) -> np.ndarray:
    """Whitened residuals: unsaturated gray, censored gray, distance, and the range
    offset's prior (``_prior_residual``)."""
    w = pb.win
    r_gray = (w.gray[pb.gray_rows] - pred.gray[pb.gray_rows]) / sig.gray[pb.gray_rows]
    fs = pb.noise.full_scale_counts
    r_sat = np.maximum(fs - pred.gray[pb.sat_rows], 0.0) / sig.gray[pb.sat_rows]
    dd = _wrap(
        w.distance_mm[pb.dist_rows] - pred.distance_mm[pb.dist_rows], pb.noise.unambiguous_range_mm
    )
    r_dist = dd / sig.distance_mm[pb.dist_rows]
    return np.concatenate([r_gray, r_sat, r_dist, _prior_residual(pb, s)])


def _row_owners(pb: _Problem) -> np.ndarray:
    """The disc each residual row belongs to (-1: the prior's row)."""
    o = pb.win.owner
    prior = np.full(_n_prior_rows(pb), -1)
    return np.concatenate([o[pb.gray_rows], o[pb.sat_rows], o[pb.dist_rows], prior])


def _disc_columns(pb: _Problem, k: int) -> np.ndarray:
    """(n_free,) bool: the free parameters that belong to disc ``k`` alone (its gain
    terms, its surround's level, its own range error)."""
    layout = pb.layout
    own = np.zeros(pb.n_params, bool)
    own[6 + G * k : 6 + G * (k + 1)] = True
    own[6 + G * layout.k + k] = True
    if layout.disc_cols.size:
        own[layout.disc_cols[k]] = True
    return own[pb.free]


def disc_blocks(
    J: np.ndarray, r: np.ndarray, owners: np.ndarray, k_count: int
) -> tuple[np.ndarray, np.ndarray]:
    """Each disc's rows' share of ``J'J`` (K, F, F) and of ``J'r`` (K, F): J (rows, F)
    and r (rows,) whitened, owners (rows,) each row's disc (-1: a prior's row, in no
    disc's share)."""
    blocks = np.zeros((k_count, J.shape[1], J.shape[1]))
    grads = np.zeros((k_count, J.shape[1]))
    for k in range(k_count):
        mine = owners == k
        blocks[k] = J[mine].T @ J[mine]
        grads[k] = J[mine].T @ r[mine]
    return blocks, grads


@dataclass(frozen=True)
class DiscDeletion:
    """What deleting each disc from the fit says of the pose covariance
    (``disc_deletion``).

    influential : (K,) bool
        The discs whose deletion moves the pose beyond ``DISC_INFLUENCE_P`` of what the
        model expects of that deletion: biased beyond their noise.
    influence_covariance : (6, 6)
        ``sum d_k d_k^T`` over the influential discs' pose moves ``d_k`` (about the error
        each put into the pose).
    variance_factor : float
        The other discs' deletion statistics over their degrees of freedom,
        ``sum D_k / sum rank_k`` (1 on average when the model holds; a model error that
        every disc shares raises it), at least 1: the factor on the Fisher covariance.
    """

    influential: np.ndarray
    influence_covariance: np.ndarray
    variance_factor: float

    def covariance(self, fisher: np.ndarray) -> np.ndarray:
        """(6, 6) the reported covariance from the Fisher one ``fisher`` (6, 6)."""
        return fisher * self.variance_factor + self.influence_covariance


def disc_deletion(
    info: np.ndarray,
    grad: np.ndarray,
    disc_info: np.ndarray,
    disc_grad: np.ndarray,
    disc_columns: Sequence[np.ndarray],
) -> DiscDeletion | None:
    """How far the pose moves when each disc is deleted from the fit, against how far the
    model expects it to move: the part of the pose covariance that the Fisher
    information misses (``DiscDeletion``).

    ``d_k`` is the pose fitted without disc k's pixels less the fitted pose, one
    Gauss-Newton step from the solution (rows of disc k and its own parameters' columns,
    ``disc_columns[k]`` (n_free,) bool, dropped; the full fit's own step, near 0 at
    convergence, taken off). Under the model ``d_k`` has the covariance ``V_k = C_-k -
    C`` (the deleted fit's pose covariance less the full one's: nested estimators), so
    ``D_k = d_k^T V_k^+ d_k`` is chi-square with the rank of ``V_k``. A disc with ``D_k``
    beyond ``DISC_INFLUENCE_P`` of that is influential: its move is added to the
    covariance. The others' ``sum D_k / sum rank_k`` is the variance factor.

    info : (n_free, n_free) ``J'J`` and grad : (n_free,) ``J'r`` of the whitened
    Jacobian and residuals at one state; disc_info : (K, n_free, n_free) and disc_grad :
    (K, n_free) the shares of each disc's rows (``disc_blocks``; a prior's rows are
    always kept). None when the information is singular or fewer than
    ``MIN_DELETION_DISCS`` discs can be deleted.

    Why: the Fisher information trusts the model at every pixel. A disc whose pixels
    are biased beyond their sigmas in a way the model can absorb (a range error of its
    own that the pose's tilt takes up, a surround the model draws wrong) leaves small
    residuals, so no residual test sees it, and the pose errs by several of its sigmas;
    deleting it moves the pose by about that error. A model error every disc shares (a
    rim drawn a little wrong everywhere, an amplitude-related range error) moves every
    deletion a little further than the model expects: the variance factor. A jackknife
    envelope of the moves (the pose stage's ``leave_one_out_covariance``) would say both,
    but its spread assumes discs of equal weight: with the paper target's large and
    small discs it is two to three times the Fisher covariance on frames the model fits
    (errors/sigmas 0.65 on finely rendered ones at 3 m), where ``D_k`` weighs each
    deletion by its own expected move.
    """
    try:
        info_inv = np.linalg.inv(info)
    except np.linalg.LinAlgError:
        return None
    full = -info_inv @ grad
    C = info_inv[:6, :6]
    try:
        L = np.linalg.cholesky(0.5 * (C + C.T))
    except np.linalg.LinAlgError:
        return None
    k_count = len(disc_columns)
    influence = np.zeros((6, 6))
    influential = np.zeros(k_count, bool)
    statistic = dof = 0.0
    deleted = 0
    for k in range(k_count):
        keep = ~disc_columns[k]
        try:
            inv_k = np.linalg.inv((info - disc_info[k])[np.ix_(keep, keep)])
        except np.linalg.LinAlgError:
            continue  # without disc k the pose is not determined: nothing to compare
        # the pose's columns are the first six of the free ones, and never a disc's own
        d = (-inv_k @ (grad - disc_grad[k])[keep])[:6] - full[:6]
        # in the pose's own sigmas (C = L L^T), so that the rank test does not mix rad^2
        # and mm^2: V_w = L^-1 (C_-k - C) L^-T, d_w = L^-1 d
        Vw = np.linalg.solve(L, np.linalg.solve(L, inv_k[:6, :6] - C).T)
        w, U = np.linalg.eigh(0.5 * (Vw + Vw.T))
        big = w > DISC_DELETION_RANK_TOL * max(float(w.max()), 0.0)
        if not np.any(big):
            continue
        deleted += 1
        z = U[:, big].T @ np.linalg.solve(L, d)
        stat = float(np.sum(z**2 / w[big]))
        rank = int(big.sum())
        if stat > chi2_limit(rank, DISC_INFLUENCE_P):
            influence += np.outer(d, d)
            influential[k] = True
        else:
            statistic += stat
            dof += rank
    if deleted < MIN_DELETION_DISCS:
        return None
    factor = max(1.0, statistic / dof) if dof > 0 else 1.0
    return DiscDeletion(influential, influence, factor)


def _pose_columns_analytic(
    pb: _Problem, s: _State, images: DiscImages, d_images: DiscImageDerivatives, pred: Prediction
) -> tuple[np.ndarray, np.ndarray]:
    """d gray (P, 6) and d distance (P, 6) over the pose from the discs' analytic image
    derivatives (``model.disc_images_with_derivatives``) through ``model.predict``: gray
    ``sum_k g_k c_k + level (1 - sum_k c_k)``, distance ``mm_per_radian arg(mixed)`` with
    ``d arg(mixed) = Im(d mixed / mixed)``; the surround's clip at 0 holds it still."""
    g = pixel_gains(s.gains, pb.basis)  # (K, P)
    level = pb.pixel_levels(s.levels)[:, None]  # (P, 1)
    covered = images.coverage.sum(axis=0)
    d_surround = np.where((covered < 1.0)[:, None], -d_images.coverage.sum(axis=0), 0.0)
    d_gray = np.einsum("kp,kpj->pj", g, d_images.coverage) + level * d_surround
    # the gains are real: the complex sum over the discs as one of (re, im) pairs
    d_disc_phasor = np.einsum("kp,kpj->pj", g, d_images.phasor.view(np.float64))
    d_mixed = d_disc_phasor.view(np.complex128) + level * (
        d_surround * images.plate_phasor[:, None] + pred.surround[:, None] * d_images.plate_phasor
    )
    inv_w = 1.0 / np.where(np.abs(pred.phasor) > 0, pred.phasor, 1.0)
    return d_gray, pb.noise.mm_per_radian * np.imag(d_mixed * inv_w[:, None])


def _pose_columns_numeric(pb: _Problem, s: _State) -> tuple[np.ndarray, np.ndarray]:
    """d gray (P, 6) and d distance (P, 6) over the pose by central differences of the
    model (twelve evaluations; steps ``ROTATION_STEP_RAD``, ``TRANSLATION_STEP_MM``):
    the check of the analytic columns."""
    p_count = pb.win.n_pixels
    d_gray = np.zeros((p_count, 6))
    d_dist = np.zeros((p_count, 6))
    steps = [ROTATION_STEP_RAD] * 3 + [TRANSLATION_STEP_MM] * 3
    for i, h in enumerate(steps):
        e = np.zeros(6)
        e[i] = h
        out = []
        for sign in (1.0, -1.0):
            R = Rotation.from_rotvec(sign * e[:3]).as_matrix() @ s.R
            out.append(pb.predict(pb.images(R, s.t_mm + sign * e[3:]), s))
        d_gray[:, i] = (out[0].gray - out[1].gray) / (2 * h)
        dd = _wrap(out[0].distance_mm - out[1].distance_mm, pb.noise.unambiguous_range_mm)
        d_dist[:, i] = dd / (2 * h)
    return d_gray, d_dist


def _jacobian(
    pb: _Problem,
    s: _State,
    images: DiscImages,
    pred: Prediction,
    sig: _Sigmas,
    d_images: DiscImageDerivatives | None = None,
) -> np.ndarray:
    """d residuals / d parameters (rows as ``_residuals``; the free parameters' columns):
    the pose's six columns from the images' analytic derivatives ``d_images`` (by central
    differences of the model when None), the gains', levels' and offsets' analytically."""
    k_count = len(pb.discs.ids)
    layout = pb.layout
    owner = pb.win.owner
    mpr = pb.noise.mm_per_radian
    if d_images is None:
        pose_gray, pose_dist = _pose_columns_numeric(pb, s)
    else:
        pose_gray, pose_dist = _pose_columns_analytic(pb, s, images, d_images, pred)
    inv_w = 1.0 / np.where(np.abs(pred.phasor) > 0, pred.phasor, 1.0)
    # d distance / d gain term = mm_per_radian Im(phasor_k basis / mixed): the basis is real
    dist_per_gain = mpr * np.imag(images.phasor * inv_w)  # (K, P)
    # the plate's level reaches a pixel through the part the plate fills
    per_level = pred.surround * pb.plate_fraction  # (P,)
    dist_per_level = mpr * np.imag(per_level * images.plate_phasor * inv_w)  # (P,)
    # rows: unsaturated gray, censored gray (a residual only below full scale), distance
    gray_px = pb.gray_pixels
    below = pred.gray[pb.sat_rows] < pb.noise.full_scale_counts
    gray_w = -np.concatenate([1.0 / sig.gray[pb.gray_rows], below / sig.gray[pb.sat_rows]])
    dist_px = pb.dist_rows
    dist_w = -1.0 / sig.distance_mm[dist_px]
    n_gray, n_dist = len(gray_px), len(dist_px)
    J = np.zeros((n_gray + n_dist + _n_prior_rows(pb), pb.n_params))
    gray_block, dist_block = J[:n_gray], J[n_gray : n_gray + n_dist]
    gain_cols = slice(6, 6 + G * k_count)  # column 6 + G k + j: disc k's gain term j
    for block, px, w, pose, per_gain, basis in (
        (gray_block, gray_px, gray_w, pose_gray, images.coverage, pb.row_basis[0]),
        (dist_block, dist_px, dist_w, pose_dist, dist_per_gain, pb.row_basis[1]),
    ):
        block[:, :6] = pose[px] * w[:, None]
        gain = per_gain[:, px, None] * basis * w[None, :, None]  # (K, rows, G)
        block[:, gain_cols] = gain.transpose(1, 0, 2).reshape(len(px), G * k_count)
    rows_g, rows_d = np.arange(n_gray), np.arange(n_dist)
    # each pixel's surround level: its owner's column
    gray_block[rows_g, 6 + G * k_count + owner[gray_px]] = per_level[gray_px] * gray_w
    dist_block[rows_d, 6 + G * k_count + owner[dist_px]] = dist_per_level[dist_px] * dist_w
    if pb.fit_offset:
        dist_block[:, layout.offset_col] = dist_w
    if layout.disc_cols.size:
        dist_block[rows_d, layout.disc_cols[owner[dist_px]]] = dist_w
    prior = J[n_gray + n_dist :]
    row = 0
    if pb.fit_offset and np.isfinite(pb.offset_sigma_mm):
        prior[0, layout.offset_col] = -1.0 / pb.offset_sigma_mm
        row = 1
    if layout.disc_cols.size:
        prior[row + np.arange(k_count), layout.disc_cols] = -1.0 / pb.disc_range_sigma_mm
    return J[:, pb.free]


def _surround_extra_var(pb: _Problem, images: DiscImages, s: _State) -> float:
    """The gray variance of the surround beyond its level (the ambient's share): the
    robust variance of the pixels no disc reaches, minus their fitted level."""
    w = pb.win
    free = (images.coverage.sum(axis=0) == 0) & (w.gray < pb.noise.full_scale_counts)
    if free.sum() < 8:
        return 0.0
    level = pb.pixel_levels(s.levels)[free]
    z = w.gray[free] - level
    var = (MAD_TO_SIGMA * np.median(np.abs(z - np.median(z)))) ** 2
    return float(max(var - np.median(np.maximum(level, 0.0)), 0.0))


def _glint_pixels(
    pb: _Problem, images: DiscImages, pred: Prediction, extra_var: float
) -> np.ndarray:
    """(P,) bool: the window pixels of bright spots in the surround that the model does
    not carry (a specular glint, a light, a marker-like reflection off the structure), at
    a solution (``images`` its discs' images, ``pred`` the model there).

    A spot is a pixel whose gray is more than ``GLINT_PEAK_SIGMA`` sigmas above the
    model, the largest in its 3 x 3 neighbourhood; its pixels are those connected to it,
    clear of the discs, more than ``GLINT_TAIL_SIGMA`` above the model. It is left out
    only when none of its pixels is a disc's or next to one (a disc's rim the model
    draws wrong, or blurs, is a model error to be seen, and a spot whose light reaches a
    rim biases the rim where it cannot be left out) and it covers at most
    ``GLINT_MAX_SHARE`` of the surround. Left in, such a spot pulls the window's
    surround level up and the disc's residuals beyond the fallback's limit (the other
    renderer's glints recording: the fit held on 15 of its 48 frames)."""
    w = pb.win
    z = (w.gray - pred.gray) / np.sqrt(_gray_variance(pred, extra_var))
    covered = images.coverage.sum(axis=0) > 0
    r0, c0 = int(w.rows.min()), int(w.cols.min())
    shape = (int(w.rows.max()) - r0 + 1, int(w.cols.max()) - c0 + 1)
    at = (w.rows - r0, w.cols - c0)
    z_img = np.full(shape, -np.inf)
    z_img[at] = z
    near_disc = np.zeros(shape, bool)
    near_disc[at] = covered
    near_disc = ndimage.binary_dilation(near_disc, structure=np.ones((3, 3), bool))
    peak = (z_img > GLINT_PEAK_SIGMA) & ~near_disc
    peak &= z_img >= ndimage.maximum_filter(z_img, size=3)
    if not peak.any():
        return np.zeros(w.n_pixels, bool)
    tail = np.zeros(shape, bool)
    tail[at] = (z > GLINT_TAIL_SIGMA) & ~covered
    labels, _ = ndimage.label(tail, structure=np.ones((3, 3), bool))
    # a spot whose pixels reach a disc's neighbours lights its rim too: not left out
    touching = np.unique(labels[tail & near_disc])
    # nor one larger than GLINT_MAX_SHARE of the surround (the model's own error: a
    # plate drawn too small, a bright structure beyond it)
    surround_px = int(np.sum(~covered))
    sizes = np.bincount(labels.ravel())
    large = np.flatnonzero(sizes > GLINT_MAX_SHARE * surround_px)
    chosen = np.setdiff1d(np.unique(labels[peak & tail]), np.union1d(touching, large))
    return np.isin(labels, chosen)[at]


def _without_pixels(pb: _Problem, left_out: np.ndarray) -> _Problem:
    """``pb`` with the pixels ``left_out`` (P,) bool in none of its residuals."""
    return replace(
        pb,
        gray_rows=pb.gray_rows[~left_out[pb.gray_rows]],
        sat_rows=pb.sat_rows[~left_out[pb.sat_rows]],
        dist_rows=pb.dist_rows[~left_out[pb.dist_rows]],
    )


def _plate_behind(discs: Discs, plate_size_mm: tuple[float, float]) -> tuple[float, float] | None:
    """The plate's size when every fitted disc's centre lies on it (a catalog whose plate
    is its target's), else None: no plate edge is modelled (one surround level per
    window). A catalog that leaves the size out reads the paper target's 990 x 550 mm
    (``Catalog``); where the real plate is larger, the pixels taken as beyond it read the
    plate's level and the two parts are one level, as without the edge."""
    half = np.asarray(plate_size_mm, float) / 2
    inside = np.all(np.abs(discs.centres_mm[:, :2]) <= half, axis=1)
    return plate_size_mm if bool(np.all(inside)) else None


def _plate_surround(
    win: Windows, images: DiscImages, saturated: np.ndarray, k_count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The surround's two parts at each window pixel (P,): the part the plate fills
    (``win.plate_fraction``) and the beyond's level times the rest, counts
    (``_Problem.pixel_levels``), and the beyond's level per window (K,) counts. The
    beyond's level is held, not fitted: the median gray of the window's pixels wholly
    beyond the plate and clear of the discs (at least ``MIN_BEYOND_PIXELS``; else those
    of all windows together, a level that one window's surround may not share). When all
    windows together have fewer, the surround is the plate's alone (fraction 1), as on a
    target whose plate fills every window. The beyond's light takes the plate's phase in
    the mixed phasor: it differs only in a distance row whose pixel holds both a disc's
    rim and the beyond, a pixel or two at the longest ranges."""
    p_count = win.n_pixels
    clear = (images.coverage.sum(axis=0) == 0) & ~saturated & (win.plate_fraction == 0)
    if clear.sum() < MIN_BEYOND_PIXELS:
        return np.ones(p_count), np.zeros(p_count), np.zeros(k_count)
    level = np.full(k_count, float(np.median(win.gray[clear])))
    for k in range(k_count):
        mine = clear & (win.owner == k)
        if mine.sum() >= MIN_BEYOND_PIXELS:
            level[k] = float(np.median(win.gray[mine]))
    return win.plate_fraction, level[win.owner] * (1.0 - win.plate_fraction), level


def _initial_linear(pb: _Problem, images: DiscImages) -> tuple[np.ndarray, np.ndarray]:
    """Gains (K, 3: level, no slope) and levels (K,) by least squares at the starting
    pose (they enter linearly)."""
    k_count = len(pb.discs.ids)
    rows = pb.gray_rows
    surround = np.clip(1.0 - images.coverage.sum(axis=0), 0.0, 1.0)
    A = np.zeros((len(rows), 2 * k_count))
    A[:, :k_count] = images.coverage[:, rows].T
    A[np.arange(len(rows)), k_count + pb.win.owner[rows]] = (surround * pb.plate_fraction)[rows]
    beyond = surround[rows] * pb.beyond_counts[rows]
    x, *_ = np.linalg.lstsq(A, pb.win.gray[rows] - beyond, rcond=None)
    g0, levels = x[:k_count], x[k_count:]
    # a disc all of whose pixels are saturated has no unsaturated gain: start at full scale
    sat_only = A[:, :k_count].sum(axis=0) < MIN_DISC_AREA_PX
    g0 = np.where(sat_only, pb.noise.full_scale_counts, g0)
    gains = np.zeros((k_count, G))
    gains[:, 0] = g0
    return gains, levels


@dataclass(frozen=True)
class _FitFrame:
    """``fit_pose_to_pixels``' frame and starting pose, checked: gray and distance_mm
    (H, W), the camera and catalog, R (3, 3) and t_mm (3,)."""

    gray: np.ndarray
    distance_mm: np.ndarray
    camera: CameraModel
    catalog: Catalog
    R: np.ndarray
    t_mm: np.ndarray


@dataclass(frozen=True)
class _FitOptions:
    """``fit_pose_to_pixels``' options, checked, as each of its fits takes them."""

    noise: PixelNoise
    fit_range_offset: bool
    range_offset_sigma_mm: float
    range_offset_mean_mm: float
    subsamples: int
    pad_px: int
    max_iterations: int
    max_marker_rms_sigma: float
    implementation: str
    jacobian: str
    disc_deletion_terms: bool


def fit_pose_to_pixels(
    gray: np.ndarray,
    distance_mm: np.ndarray,
    camera: CameraModel,
    catalog: Catalog,
    R: np.ndarray,
    t_mm: np.ndarray,
    catalog_ids: Sequence[int],
    *,
    noise: PixelNoise | None = None,
    fit_range_offset: bool = False,
    range_offset_sigma_mm: float = float("inf"),
    range_offset_mean_mm: float = 0.0,
    exclude_unmatched: bool = True,
    subsamples: int = SUBSAMPLES,
    pad_px: int = WINDOW_PAD_PX,
    max_iterations: int = MAX_ITERATIONS,
    max_marker_rms_sigma: float = MAX_MARKER_RMS_SIGMA,
    implementation: str = "compiled",
    jacobian: str = "analytic",
    disc_deletion_terms: bool = True,
) -> PixelFitResult:
    """Refine a pose on the raw pixels of the matched reflectors.

    Parameters
    ----------
    gray : ndarray of shape (H, W)
        Gray (amplitude) image, counts; at ``noise.full_scale_counts`` saturated.
    distance_mm : ndarray of shape (H, W)
        Radial distance image, mm, NaN where invalid.
    camera : CameraModel
    catalog : Catalog
    R : ndarray of shape (3, 3); t_mm : ndarray of shape (3,)
        The starting pose ``T_camera_target`` (the centroid pipeline's).
    catalog_ids : sequence of int
        The matched reflectors' catalog ids (at least three).
    noise : PixelNoise, optional
        The sensor's noise model (default: ``PixelNoise()``, everything measured on the
        frame but the modulation frequency).
    fit_range_offset : bool
        Fit one range offset common to all distance pixels (an uncalibrated camera).
    range_offset_sigma_mm : float
        That offset's prior sigma, mm (the camera's range-bias sigma: the pose
        pipeline's ``range_bias_sigma_mm``); inf: no prior, the offset is free.
    range_offset_mean_mm : float
        That prior's mean, mm (the pipeline's ``range_offset_mean_mm``): where the
        offset starts, and the offset taken out of every distance pixel when it is not
        fitted.
    exclude_unmatched : bool
        Leave out the pixels near the predicted image of catalog discs not in
        ``catalog_ids`` (the model does not carry them).
    subsamples : int
        S: sub-cells per pixel side on the discs' rims.
    pad_px : int
        Window margin beyond each disc's predicted bounding box, px.
    max_iterations : int
    max_marker_rms_sigma : float
        A disc whose residual RMS (sigmas) exceeds it makes the fit fall back.
    implementation : str
        "compiled" (the discs' images by ``kernels.images``) or "reference" (the same
        arithmetic in NumPy, ``model.disc_images``).
    jacobian : str
        "analytic" (the pose's Jacobian columns from the images' analytic derivatives,
        ``model.disc_images_with_derivatives``: one model call an iteration) or
        "central-differences" (twelve model calls an iteration: the check of the
        analytic one; the converged poses agree to a small part of a sigma).
    disc_deletion_terms : bool
        Widen the covariance by what deleting each disc says of it (``disc_deletion``:
        the moves of the influential discs, the others' variance factor); False: the
        inverse Fisher information alone (to test the noise model's own terms).

    Returns
    -------
    PixelFitResult
        ``ok`` False (with ``reason``) when the fit could not start, did not converge or
        a disc disagrees with the model: keep the starting pose then.

    A first fit over every matched disc that fails only on discs it names (pixels the
    model does not explain: a glint on a rim, an arm over a disc; a dark disc; not a
    clipped core, ``_blamed``) is fitted again from the starting pose without the worst
    of them (the largest residual RMS: one disc's error drags its neighbours' residuals
    up too), its pixels left out, and so on while at least ``MIN_DELETION_DISCS`` discs
    remain (so that deleting each can still check the covariance; a fit that did not
    converge counts, since a disc it cannot explain is what holds it back). ``left_out``
    names the discs left out and ``left_out_reason`` why, disc by disc; when no fit
    holds, the first's result comes back with every reason. The fits without a disc
    leave out the pixels of every catalog disc they do not fit (as
    ``exclude_unmatched`` does), whatever ``exclude_unmatched`` says.
    """

    noise = PixelNoise() if noise is None else noise
    gray = np.asarray(gray)
    distance_mm = np.asarray(distance_mm)
    if gray.shape != camera.shape or distance_mm.shape != camera.shape:
        raise ValueError(
            f"gray {gray.shape} and distance_mm {distance_mm.shape} must have the camera's "
            f"shape {camera.shape}"
        )
    R = np.asarray(R, float)
    t_mm = np.asarray(t_mm, float).reshape(-1)
    if R.shape != (3, 3) or t_mm.shape != (3,):
        raise ValueError(f"R must be (3, 3) and t_mm (3,), got {R.shape} and {t_mm.shape}")
    if implementation not in ("compiled", "reference"):
        raise ValueError(
            f"implementation must be 'compiled' or 'reference', got {implementation!r}"
        )
    if jacobian not in ("analytic", "central-differences"):
        raise ValueError(f"jacobian must be 'analytic' or 'central-differences', got {jacobian!r}")
    if not range_offset_sigma_mm > 0:
        raise ValueError(f"range_offset_sigma_mm must be positive, got {range_offset_sigma_mm}")
    if subsamples < 1:
        raise ValueError(f"subsamples must be >= 1, got {subsamples}")
    opts = _FitOptions(
        noise=noise,
        fit_range_offset=fit_range_offset,
        range_offset_sigma_mm=range_offset_sigma_mm,
        range_offset_mean_mm=range_offset_mean_mm,
        subsamples=subsamples,
        pad_px=pad_px,
        max_iterations=max_iterations,
        max_marker_rms_sigma=max_marker_rms_sigma,
        implementation=implementation,
        jacobian=jacobian,
        disc_deletion_terms=disc_deletion_terms,
    )

    frame = _FitFrame(gray, distance_mm, camera, catalog, R, t_mm)

    def fit(ids: Sequence[int], exclude: bool) -> PixelFitResult:
        return _fit_discs(frame, ids, exclude, opts)

    first = fit(catalog_ids, exclude_unmatched)
    res, left, reasons = first, [], []
    while not res.ok and len(res.marker_rms_sigma):  # a fit that started, and failed
        blamed = _blamed(res, max_marker_rms_sigma)
        if not np.any(blamed) or len(res.catalog_ids) - 1 < MIN_DELETION_DISCS:
            break
        # the worst first: one disc's error drags its neighbours' residuals up too
        rms = np.where(blamed, np.nan_to_num(res.marker_rms_sigma, nan=np.inf), -np.inf)
        k = int(np.argmax(rms))
        worst = int(res.catalog_ids[k])
        left.append(worst)
        why = "dark" if _dark(res, res.gray_extra_var)[k] else "unexplained"
        rms_k = res.marker_rms_sigma[k]
        reasons.append(f"{worst} ({why}, residual RMS {rms_k:.1f} sigma; {res.reason})")
        res = fit([int(i) for i in res.catalog_ids if int(i) != worst], True)
    if res.ok and left:
        return replace(res, left_out=np.array(left), left_out_reason="; then ".join(reasons))
    if left:
        return replace(first, reason=f"{first.reason}; without markers {left}: {res.reason}")
    return first


def _fit_discs(
    frame: _FitFrame, catalog_ids: Sequence[int], exclude_unmatched: bool, opts: _FitOptions
) -> PixelFitResult:
    """``fit_pose_to_pixels`` on the discs ``catalog_ids``, once (its inputs checked, in
    ``frame``; its options in ``opts``)."""
    gray, distance_mm, camera, catalog = frame.gray, frame.distance_mm, frame.camera, frame.catalog
    R, t_mm = frame.R, frame.t_mm
    discs = Discs.from_catalog(catalog, catalog_ids)
    start = PixelFitResult(ok=False, reason="", R=R, t_mm=t_mm, catalog_ids=discs.ids)
    if len(discs.ids) < MIN_MARKERS:
        return replace(start, reason=f"{len(discs.ids)} markers: the fit needs {MIN_MARKERS}")
    centres_cam = discs.centres_mm @ R.T + t_mm
    if np.any(centres_cam[:, 2] <= 0):
        return replace(start, reason="a matched disc is behind the camera at the start pose")
    others = None
    if exclude_unmatched:
        rest = [int(i) for i in catalog.ids if int(i) not in set(discs.ids.tolist())]
        if rest:
            o = Discs.from_catalog(catalog, rest)
            front = (o.centres_mm @ R.T + t_mm)[:, 2] > 0
            others = Discs(o.ids[front], o.centres_mm[front], o.radii_mm[front])
    win = build_windows(
        gray,
        distance_mm,
        camera,
        discs,
        R,
        t_mm,
        others=others,
        pad_px=opts.pad_px,
        subsamples=opts.subsamples,
        plate_size_mm=_plate_behind(discs, catalog.plate_size_mm),
    )
    saturated = win.gray >= opts.noise.full_scale_counts
    reference_mm = float(np.linalg.norm(t_mm))
    rims = predicted_rims(camera, R, t_mm, discs)
    centre_px = rims.mean(axis=1)  # (K, 2)
    radius_px = np.max(np.linalg.norm(rims - centre_px[:, None], axis=2), axis=1)
    uv = np.column_stack([win.cols, win.rows]).astype(float)
    k_count = len(discs.ids)
    free = np.ones(6 + (G + 1) * k_count + (1 if opts.fit_range_offset else 0), bool)
    for k in range(k_count):  # a small disc's gain shape is not measurable
        terms = 1 if radius_px[k] < GAIN_SLOPE_MIN_RADIUS_PX else 3
        terms = G if radius_px[k] >= GAIN_CURVE_MIN_RADIUS_PX else terms
        free[6 + G * k + terms : 6 + G * (k + 1)] = False
    pb0 = _Problem(
        discs=discs,
        win=win,
        gray_rows=np.flatnonzero(~saturated),
        sat_rows=np.flatnonzero(saturated),
        dist_rows=np.zeros(0, int),
        noise=opts.noise,
        reference_mm=reference_mm,
        fit_offset=opts.fit_range_offset,
        offset_sigma_mm=float(opts.range_offset_sigma_mm),
        offset_mean_mm=float(opts.range_offset_mean_mm),
        compiled=opts.implementation == "compiled",
        near_flat=win.near_flat,
        numeric_jacobian=opts.jacobian == "central-differences",
        basis=gain_basis(uv[None] - centre_px[:, None], radius_px),
        free=free,
        plate_fraction=np.ones(win.n_pixels),
        beyond_counts=np.zeros(win.n_pixels),
    )
    images = pb0.images(R, t_mm)
    area = images.coverage.sum(axis=1)
    if np.any(area < MIN_DISC_AREA_PX):
        lost = discs.ids[area < MIN_DISC_AREA_PX].tolist()
        return replace(start, reason=f"markers {lost} are not in the image at the start pose")
    covered = images.coverage.sum(axis=0)
    usable_distance = np.isfinite(win.distance_mm) & ~saturated & (covered >= DISTANCE_MIN_COVERAGE)
    plate, beyond, beyond_level = _plate_surround(win, images, saturated, k_count)
    # a window the plate does not reach has no plate level to fit
    seen_plate = plate * np.clip(1.0 - covered, 0.0, 1.0)
    on_plate = np.bincount(win.owner, weights=seen_plate, minlength=k_count) >= MIN_PLATE_PIXELS
    free = free.copy()
    free[6 + G * k_count : 6 + (G + 1) * k_count] &= on_plate
    pb = replace(
        pb0,
        dist_rows=np.flatnonzero(usable_distance),
        plate_fraction=plate,
        beyond_counts=beyond,
        free=free,
    )
    gains, levels = _initial_linear(pb, images)
    # a held level is its window's surround: the beyond's (the dark test reads it)
    levels = np.where(on_plate, levels, beyond_level)
    state = _State(
        R=R,
        t_mm=t_mm,
        gains=gains,
        levels=levels,
        offset_mm=float(opts.range_offset_mean_mm),
        disc_offsets_mm=np.zeros(k_count),
    )
    extra_var = (
        _surround_extra_var(pb, images, state)
        if opts.noise.gray_extra_var is None
        else float(opts.noise.gray_extra_var)
    )

    solved = _levenberg_marquardt(
        pb,
        state,
        images,
        extra_var,
        np.zeros(k_count),
        opts.max_iterations,
        START_STEP_TOLERANCE_SIGMA2,
    )
    # bright spots in the surround the model does not carry (glints): left out, fitted again
    pred = pb.predict(solved.images, solved.state)
    glints = _glint_pixels(pb, solved.images, pred, extra_var)
    if np.any(glints):
        pb = _without_pixels(pb, glints)
        again = _levenberg_marquardt(
            pb,
            solved.state,
            solved.images,
            extra_var,
            np.zeros(k_count),
            opts.max_iterations,
            START_STEP_TOLERANCE_SIGMA2,
        )
        solved = replace(again, iterations=solved.iterations + again.iterations)
        pred = pb.predict(solved.images, solved.state)
    # the model errors the frame shows at the first solution; then fitted again with them
    st, im = solved.state, solved.images
    rim = _rim_sensitivity(pb, im, pred, st)
    crowded = _crowded(discs)
    if opts.noise.coverage_sigma is None:
        coverage_sigma = _measured_coverage_sigma(
            pb, pred, _sigmas(pb, pred, extra_var), rim, crowded
        )
    else:
        coverage_sigma = np.full(k_count, float(opts.noise.coverage_sigma))
    disc_range_sigma = opts.noise.disc_range_sigma_mm
    if disc_range_sigma is None:
        sig = _sigmas(pb, pred, extra_var, rim, coverage_sigma)
        disc_range_sigma = _measured_disc_range_sigma(pb, pred, sig)
    if disc_range_sigma > 0:
        pb = replace(
            pb,
            disc_range_sigma_mm=disc_range_sigma,
            free=np.concatenate([pb.free, np.ones(k_count, bool)]),
        )
    # with them (without any, the starting solve's own cost), to the full tolerance
    again = _levenberg_marquardt(pb, st, im, extra_var, coverage_sigma, opts.max_iterations)
    solved = replace(again, iterations=solved.iterations + again.iterations)
    if solved.held_range_k_mm is not None:  # the noise constant the covariance is with
        pb = replace(pb, noise=replace(pb.noise, range_k_mm=solved.held_range_k_mm))
    state, images = solved.state, solved.images
    pred = pb.predict(images, state)
    sig = _sigmas(pb, pred, extra_var, _rim_sensitivity(pb, images, pred, state), coverage_sigma)
    r = _residuals(pb, pred, sig, state)
    owners = _row_owners(pb)
    rms = np.array(
        [
            np.sqrt(np.mean(r[owners == k] ** 2)) if np.any(owners == k) else np.nan
            for k in range(k_count)
        ]
    )
    covariance = None
    offset_sigma = 0.0
    if solved.info is not None:
        try:
            info_inv = np.linalg.inv(solved.info)
        except np.linalg.LinAlgError:
            info_inv = None
        if info_inv is not None:
            covariance = 0.5 * (info_inv[:6, :6] + info_inv[:6, :6].T)
            if pb.layout.offset_col >= 0:
                col = int(np.count_nonzero(pb.free[: pb.layout.offset_col]))
                offset_sigma = float(np.sqrt(max(info_inv[col, col], 0.0)))
    deletion = None
    if (
        opts.disc_deletion_terms
        and covariance is not None
        and solved.info is not None
        and solved.last is not None
    ):
        # each disc's share of the last linearisation (the one ``info`` is of)
        _, grad, _, _, shares = _linearised(pb, solved.last, per_disc=True)
        assert shares is not None
        deletion = disc_deletion(
            solved.info, grad, *shares, [_disc_columns(pb, k) for k in range(k_count)]
        )
        if deletion is not None:
            covariance = deletion.covariance(covariance)
    result = PixelFitResult(
        ok=False,
        reason="",
        R=state.R,
        t_mm=state.t_mm,
        covariance=covariance,
        catalog_ids=discs.ids,
        marker_rms_sigma=rms,
        gains=state.gains,
        levels=state.levels,
        range_offset_mm=state.offset_mm,
        range_offset_sigma_mm=offset_sigma,
        iterations=solved.iterations,
        converged=solved.converged,
        n_gray_pixels=len(pb.gray_rows),
        n_distance_pixels=len(pb.dist_rows),
        n_saturated=len(pb.sat_rows),
        n_glint_pixels=int(glints.sum()),
        clipped_share=_clipped_share(pb, images),
        range_k_mm=sig.range_k_mm,
        gray_extra_var=extra_var,
        coverage_sigma=float(np.median(coverage_sigma)),
        disc_range_sigma_mm=float(disc_range_sigma),
        influential=np.zeros(k_count, bool) if deletion is None else deletion.influential,
        deletion_variance_factor=1.0 if deletion is None else deletion.variance_factor,
        deletion_checked=deletion is not None,
    )
    result = replace(result, **_verdict(result, extra_var, opts.max_marker_rms_sigma))
    return result


@dataclass(frozen=True)
class _Solved:
    state: _State
    images: DiscImages
    info: np.ndarray | None  # Fisher information at the last iteration's Jacobian
    iterations: int
    converged: bool
    # where the last iteration linearised the model (before its step): ``info``'s state
    last: _Linearisation | None = None
    # the distance's noise constant the solve held (``NOISE_FREEZE_ITERATIONS``), None
    # when it measured it at every iteration; ``info`` and ``last`` are with it
    held_range_k_mm: float | None = None


@dataclass(frozen=True)
class _SolveNoise:
    """The noise model's parts one solve holds fixed: the gray's extra variance, the rim's
    model error per disc (K,) with the rim's sensitivity at the solve's start (None
    without it), and the same as ``kernels.normal`` takes them (None: the NumPy path)."""

    extra_var: float
    coverage_sigma: np.ndarray
    rim: _RimSensitivity | None
    kernel: tuple[FitRecord, FitConstants] | None


@dataclass(frozen=True)
class _Linearisation:
    """A state, its discs' images and their pose derivatives (None: by central
    differences), and the solve's noise model: where an iteration linearises."""

    state: _State
    images: DiscImages
    d_images: DiscImageDerivatives | None
    noise: _SolveNoise


def _levenberg_marquardt(
    pb: _Problem,
    state: _State,
    images: DiscImages,
    extra_var: float,
    coverage_sigma: np.ndarray,
    max_iterations: int,
    step_tolerance_sigma2: float = STEP_TOLERANCE_SIGMA2,
) -> _Solved:
    """Levenberg-Marquardt from ``state`` (``images`` its discs' images) with the noise
    model's sigmas re-evaluated at each iteration (the distance's noise constant, when
    measured, for the first ``NOISE_FREEZE_ITERATIONS``); the rim's model error, when
    ``coverage_sigma`` > 0, with the rim's sensitivity of the starting state (so that the
    weights of the rim pixels do not follow the fit from one iteration to the next).
    Converged at a step shorter than ``step_tolerance_sigma2`` in its own sigmas."""
    rim = None
    if np.any(coverage_sigma > 0):
        rim = _rim_sensitivity(pb, images, pb.predict(images, state), state)
    kernel = None
    if pb.compiled and not pb.numeric_jacobian:
        kernel = (_fit_record(pb, rim, coverage_sigma), _fit_constants(pb, extra_var))
    noise = _SolveNoise(extra_var, coverage_sigma, rim, kernel)
    damping = INITIAL_DAMPING
    converged = False
    iterations = 0
    info = None
    last = None
    held = None
    for iteration in range(1, max_iterations + 1):
        iterations = iteration
        d_images = None
        if not pb.numeric_jacobian:
            images, d_images = pb.images_with_derivatives(state.R, state.t_mm)
        last = _Linearisation(state, images, d_images, noise)
        info, grad, cost, sig, _ = _linearised(pb, last, per_disc=False)
        if iteration == NOISE_FREEZE_ITERATIONS and pb.noise.range_k_mm is None:
            # held from here on (``NOISE_FREEZE_ITERATIONS``): the distance weights no
            # longer follow the residuals' median from step to step
            held = sig.range_k_mm
            pb = replace(pb, noise=replace(pb.noise, range_k_mm=held))
            if kernel is not None:
                kernel = (kernel[0], kernel[1]._replace(range_k_mm=sig.range_k_mm))
            noise = _SolveNoise(extra_var, coverage_sigma, rim, kernel)
        diag = np.maximum(np.diag(info), 1e-12)
        accepted = False
        for _ in range(MAX_DAMPING_TRIES):
            try:
                step = np.linalg.solve(info + damping * np.diag(diag), -grad)
            except np.linalg.LinAlgError:
                damping *= DAMPING_UP
                continue
            delta = np.zeros(pb.n_params)
            delta[pb.free] = step
            trial = state.stepped(delta, pb.layout)
            trial_images = pb.images(trial.R, trial.t_mm)
            if kernel is not None:
                trial_cost = normal_kernel.trial_cost(
                    trial_images.coverage,
                    trial_images.phasor,
                    trial_images.plate_phasor,
                    _nuisance_record(trial),
                    sig.gray,
                    sig.distance_mm,
                    *kernel,
                )
            else:
                trial_pred = pb.predict(trial_images, trial)
                trial_cost = float(np.sum(_residuals(pb, trial_pred, sig, trial) ** 2))
            if trial_cost <= cost:
                state, images, accepted = trial, trial_images, True
                damping = max(damping * DAMPING_DOWN, 1e-9)
                break
            damping *= DAMPING_UP
        step2 = float(step @ info @ step) if accepted else 0.0
        if not accepted or step2 < step_tolerance_sigma2:
            # no step lowers the cost any more, or the last one was negligible
            converged = True
            break
    return _Solved(state, images, info, iterations, converged, last, held)


def _image_record(images: DiscImages, d_images: DiscImageDerivatives) -> ImageRecord:
    """The discs' images and their pose derivatives as ``kernels.normal`` takes them."""
    return ImageRecord(
        coverage=images.coverage,
        phasor=images.phasor,
        plate=images.plate_phasor,
        d_coverage=d_images.coverage,
        d_phasor=d_images.phasor,
        d_plate=d_images.plate_phasor,
    )


def _linearised(
    pb: _Problem, lin: _Linearisation, per_disc: bool = True
) -> tuple[np.ndarray, np.ndarray, float, _Sigmas, tuple[np.ndarray, np.ndarray] | None]:
    """The normal equations at ``lin``: ``J'J``, ``J'r``, ``r'r``, the sigmas, and with
    ``per_disc`` each disc's shares of ``J'J`` and ``J'r`` (``disc_blocks``). By
    ``kernels.normal`` when the solve has its inputs and the derivatives are analytic,
    else from J in NumPy."""
    noise = lin.noise
    if noise.kernel is not None and lin.d_images is not None:
        out = normal_kernel.normal_equations(
            _image_record(lin.images, lin.d_images),
            _nuisance_record(lin.state),
            *noise.kernel,
            per_disc,
        )
        sig = _Sigmas(out.sigma_gray, out.sigma_distance, float(out.range_k_mm))
        shares = (out.disc_info, out.disc_grad) if per_disc else None
        return out.info, out.grad, float(out.cost), sig, shares
    pred = pb.predict(lin.images, lin.state)
    sig = _sigmas(pb, pred, noise.extra_var, noise.rim, noise.coverage_sigma)
    r = _residuals(pb, pred, sig, lin.state)
    J = _jacobian(pb, lin.state, lin.images, pred, sig, lin.d_images)
    shares = disc_blocks(J, r, _row_owners(pb), len(pb.discs.ids)) if per_disc else None
    return J.T @ J, J.T @ r, float(r @ r), sig, shares


def _fit_record(pb: _Problem, rim: _RimSensitivity | None, coverage_sigma: np.ndarray) -> FitRecord:
    """The problem as ``kernels.normal`` takes it, with the rim's model error of
    ``_sigmas`` (the rim's sensitivity held over the iterations)."""
    p_count = pb.win.n_pixels
    edge_gray = edge_distance = np.zeros(p_count)
    if rim is not None and np.any(coverage_sigma > 0):
        edge_gray = np.einsum("k,kp->p", coverage_sigma**2, rim.gray2_k)
        edge_distance = np.einsum("k,kp->p", coverage_sigma**2, rim.distance2_k)
    free_index = np.full(pb.n_params, -1, np.int64)
    free_index[pb.free] = np.arange(int(pb.free.sum()))
    return FitRecord(
        gray=np.ascontiguousarray(pb.win.gray, float),
        distance_mm=np.ascontiguousarray(pb.win.distance_mm, float),
        owner=pb.win.owner.astype(np.int64),
        basis=np.ascontiguousarray(pb.basis, float),
        gray_rows=pb.gray_rows.astype(np.int64),
        sat_rows=pb.sat_rows.astype(np.int64),
        dist_rows=pb.dist_rows.astype(np.int64),
        free_index=free_index,
        edge_var_gray=np.ascontiguousarray(edge_gray, float),
        edge_var_distance=np.ascontiguousarray(edge_distance, float),
        plate_fraction=np.ascontiguousarray(pb.plate_fraction, float),
        beyond_counts=np.ascontiguousarray(pb.beyond_counts, float),
    )


def _fit_constants(pb: _Problem, extra_var: float) -> FitConstants:
    """The problem's scalars as ``kernels.normal`` takes them."""
    layout = pb.layout
    k = pb.noise.range_k_mm
    return FitConstants(
        mm_per_radian=float(pb.noise.mm_per_radian),
        reference_mm=float(pb.reference_mm),
        unambiguous_range_mm=float(pb.noise.unambiguous_range_mm),
        full_scale_counts=float(pb.noise.full_scale_counts),
        extra_var=float(extra_var),
        range_k_mm=float("nan") if k is None else float(k),
        offset_col=int(layout.offset_col),
        offset_sigma_mm=float(pb.offset_sigma_mm),
        offset_mean_mm=float(pb.offset_mean_mm),
        disc_col=int(layout.disc_cols[0]) if layout.disc_cols.size else -1,
        disc_range_sigma_mm=float(pb.disc_range_sigma_mm),
    )


def _nuisance_record(s: _State) -> NuisanceRecord:
    """The state's nuisance parameters as ``kernels.normal`` takes them."""
    return NuisanceRecord(
        gains=np.ascontiguousarray(s.gains, float),
        levels=np.ascontiguousarray(s.levels, float),
        offset_mm=float(s.offset_mm),
        disc_offsets_mm=np.ascontiguousarray(s.disc_offsets_mm, float),
    )


def _clipped_share(pb: _Problem, images: DiscImages) -> np.ndarray:
    """(K,) each disc's share of the pixels it covers wholly (coverage at least ``1 -
    RIM_COVERAGE_EPS``) whose gray is saturated; NaN for a disc that covers none."""
    inside = images.coverage >= 1.0 - RIM_COVERAGE_EPS  # (K, P)
    saturated = np.zeros(pb.win.n_pixels, bool)
    saturated[pb.sat_rows] = True
    n = inside.sum(axis=1)
    clipped = (inside & saturated[None]).sum(axis=1)
    return np.where(n > 0, clipped / np.maximum(n, 1), np.nan)


def _crowded(discs: Discs) -> np.ndarray:
    """(K,) bool: discs whose rim comes within ``CROWDED_GAP_MM`` of another's on the
    target (across its plane): where discs raised to different heights may hide each
    other's rim at an angle, which the model does not draw."""
    xy = discs.centres_mm[:, :2]
    gap = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    gap -= discs.radii_mm[:, None] + discs.radii_mm[None]
    np.fill_diagonal(gap, np.inf)
    return np.min(gap, axis=1) < CROWDED_GAP_MM if len(gap) > 1 else np.zeros(len(gap), bool)


def _unexplained(res: PixelFitResult, max_rms: float) -> np.ndarray:
    """(K,) bool: the discs whose pixels the model does not explain: residual RMS beyond
    ``max_rms`` sigmas, or a disc far worse than its siblings (over
    ``RELATIVE_RMS_FACTOR`` times their median and ``RELATIVE_RMS_MIN_SIGMA``): not one of
    them (a glint on or beside it; the frame's rim model error is the discs' median, so
    it cannot hide in it)."""
    rms = res.marker_rms_sigma
    if not np.any(np.isfinite(rms)):
        return np.zeros(len(rms), bool)
    typical = float(np.nanmedian(rms))
    unlike = (rms > RELATIVE_RMS_MIN_SIGMA) & (rms > RELATIVE_RMS_FACTOR * typical)
    return (rms > max_rms) | unlike


def _dark(res: PixelFitResult, extra_var: float) -> np.ndarray:
    """(K,) bool: discs whose fitted gain is within ``MIN_CONTRAST_SIGMA`` of their
    surround's noise (covered, occluded)."""
    surround_sigma = np.sqrt(np.maximum(res.levels, 0.0) + extra_var + QUANTISATION_VAR)
    return (res.gains[:, 0] - res.levels) < MIN_CONTRAST_SIGMA * surround_sigma


def _clipped(res: PixelFitResult) -> np.ndarray:
    """(K,) bool: discs with a clipped core (``MAX_CLIPPED_CORE_SHARE``; NaN: no core)."""
    return np.nan_to_num(res.clipped_share) > MAX_CLIPPED_CORE_SHARE


def _blamed(res: PixelFitResult, max_rms: float) -> np.ndarray:
    """(K,) bool: the discs a failed fit names that it may be fitted without
    (``_verdict``'s rules: unexplained, dark); none when a core is clipped, since a
    fixed exposure that clips one marker leaves the others' rims near full scale too
    (leaving the clipped ones out and fitting the rest on the physics study's
    saturating frames held on 15 % of them, with one pose confidently wrong)."""
    if np.any(_clipped(res)):
        return np.zeros(len(res.catalog_ids), bool)
    return _unexplained(res, max_rms) | _dark(res, res.gray_extra_var)


def _verdict(res: PixelFitResult, extra_var: float, max_rms: float) -> dict:
    """ok and reason of a finished fit (``fit_pose_to_pixels``' fallback rules); the
    reason names every rule that failed, the discs beyond their noise first. The rules:
    a disc's residual RMS beyond ``max_rms`` or unlike its siblings' (``_unexplained``);
    a disc with a clipped core (``res.clipped_share`` over ``MAX_CLIPPED_CORE_SHARE``:
    the fit is overconfident there, NEES/6 17.8 on the saturating family, even though
    its residuals look clean, RMS 0.6-1.9); no convergence; a singular information
    matrix; then a dark disc."""
    reasons = []
    rms = res.marker_rms_sigma
    bad = rms > max_rms
    unlike = _unexplained(res, max_rms) & ~bad
    if np.any(bad):
        worst = ", ".join(
            f"{i} ({v:.1f})" for i, v in zip(res.catalog_ids[bad], rms[bad], strict=True)
        )
        reasons.append(f"residual RMS beyond {max_rms:g} sigma at markers {worst}")
    typical = float(np.nanmedian(rms)) if np.any(np.isfinite(rms)) else np.nan
    if np.any(unlike):
        worst = ", ".join(
            f"{i} ({v:.1f})" for i, v in zip(res.catalog_ids[unlike], rms[unlike], strict=True)
        )
        reasons.append(
            f"residual RMS over {RELATIVE_RMS_FACTOR:g}x the discs' median ({typical:.1f} "
            f"sigma) at markers {worst}"
        )
    clipped = _clipped(res)
    if np.any(clipped):
        reasons.append(
            f"markers {res.catalog_ids[clipped].tolist()} have clipped cores (over "
            f"{MAX_CLIPPED_CORE_SHARE:.0%} of their wholly covered pixels saturated): their "
            "gains are seen only on their rims' outer pixels, where the rim's model error "
            "moves the pose beyond its covariance"
        )
    if not res.converged:
        reasons.append(f"not converged in {res.iterations} iterations")
    if res.covariance is None or not np.all(np.isfinite(res.covariance)):
        reasons.append("singular information matrix")
    if reasons:
        return {"ok": False, "reason": "; ".join(reasons)}
    dark = _dark(res, extra_var)
    if np.any(dark):
        return {"ok": False, "reason": f"markers {res.catalog_ids[dark].tolist()} are dark"}
    return {"ok": True, "reason": ""}
