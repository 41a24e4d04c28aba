"""The typed records the compiled kernels of several stages take and return instead of
long positional argument lists and result tuples (a stage's own records are in its
``records.py``).

Each is a ``typing.NamedTuple`` (numba compiles them as tuples with named fields, so a
kernel reads ``camera.fx`` rather than argument 17), built by keyword in one place
(``camera_record``, ``catalog_record`` here; the §5 settings in
``tofpose.stages.pose.solve.fit_settings``, the sigma constants in
``tofpose.stages.extraction.uncertainty.kernel_constants``, the range correction in
``tofpose.calibration.range.correction_kernel_arguments``, the gate settings in
``tofpose.stages.extraction.extraction``, the persistence history in
``tofpose.stages.persistence.persistence.Persistence.history``) and passed whole: two
settings swapped by position cannot be written. A setting keeps its
``PipelineConfig`` name from the configuration to the kernel.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class CameraRecord(NamedTuple):
    """The camera as kernels read it: pinhole intrinsics fx, fy, cx, cy (px), the
    distortion ``dist`` (5,) (k1, k2, p1, p2, k3), ``K`` (3, 3), the unit bearing of
    every pixel ``pixel_bearings`` (H * W, 3), row-major, and the image's ``width`` W
    and ``height`` H (px)."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: np.ndarray
    K: np.ndarray
    pixel_bearings: np.ndarray
    width: int
    height: int
    full_scale_counts: float


class CatalogRecord(NamedTuple):
    """The catalog as kernels read it: reflector centres ``xyz`` (N, 3) mm in the target
    frame and their radii ``radii_mm`` (N,)."""

    xyz: np.ndarray
    radii_mm: np.ndarray


class SigmaConstants(NamedTuple):
    """The measurement sigmas' floors and constants (``tofpose.stages.extraction.uncertainty``,
    each field named as its setting or constant there): centroid_sigma_floor_px and
    range_sigma_floor_mm the floors (``PipelineConfig``'s), single_pixel_sigma_px a
    one-pixel blob's centroid sigma, split_centroid_px a split blob's, pool_min_pixels the
    valid ranges from which a blob's spread joins the pooled noise model,
    median_efficiency the median's efficiency, uncalibrated_range_sigma_mm the range sigma
    when nothing calibrates the model."""

    centroid_sigma_floor_px: float
    range_sigma_floor_mm: float
    single_pixel_sigma_px: float
    split_centroid_px: float
    pool_min_pixels: int
    median_efficiency: float
    uncalibrated_range_sigma_mm: float


class PersistenceHistory(NamedTuple):
    """The persistence history and its settings as the kernels read them
    (``Persistence.history``): ``gray``, ``distance`` ((H, W) float32 each), ``mask``
    ((H * W,) bool each) and ``centroids`` ((m, 2) float64 each) are tuples of one length
    (K - 1, at least 1), newest first, of which the first ``n_frames`` are real frames (the
    rest pad with the current frame's arrays and are never read);
    ``motion_tolerance_px`` and ``c_min`` are ``PersistenceConfig``'s; ``scratch_gray``
    and ``scratch_distance`` ((H, W) float32) the two frames the compiled measurement
    writes I-bar and D-bar into where they are read (``Persistence.scratch``, lent to
    every frame)."""

    gray: tuple
    distance: tuple
    mask: tuple
    centroids: tuple
    n_frames: int
    motion_tolerance_px: float
    c_min: int
    scratch_gray: np.ndarray
    scratch_distance: np.ndarray


class FrameRecord(NamedTuple):
    """A checked frame as the measurement kernels read it: ``gray`` and ``distance``
    ((H, W) float32: counts and mm, NaN where invalid), its ``background`` level and its
    no-return (``dark``) level, counts (``extraction.FrameStats``)."""

    gray: np.ndarray
    distance: np.ndarray
    background: float
    dark: float


class RangeCorrectionRecord(NamedTuple):
    """A camera's calibrated range correction as ``stages.persistence.kernels.range_correction
    .corrected_ranges`` takes it: ``apply`` (False: none), its ``model`` (4,),
    ``harmonics`` (H, 2) and per-pixel ``offsets`` (H * W,) or (0,)."""

    apply: bool
    model: np.ndarray
    harmonics: np.ndarray
    offsets: np.ndarray


class FitSettings(NamedTuple):
    """The settings of §5 as the compiled solve reads them (``stages.pose.kernels.solve.
    solve_pairs`` and the fit it runs, ``stages.pose.kernels.pose.fit_with_outliers``),
    built by ``stages.pose.solve.fit_settings``; each field carries the
    ``PipelineConfig`` setting of its name (documented there), but:

    refinement : 0 none, 1 maximum likelihood, 2 the paper's line of sight
    (``stages.pose.constants.REFINE_NONE``, ``REFINE_ML``, ``REFINE_LOS``; the
    setting's "none", "ml", "los");
    step_sigma2 : the ML iteration's convergence threshold (squared step in sigmas;
    ``stages.pose.pose.STEP_SIGMA2``);
    min_matches : ``MatchingConfig.min_matches``, the fewest reflectors the outlier step
    leaves."""

    refinement: int
    los_tolerance: float
    step_sigma2: float
    correct_perspective_bias: bool
    mixed_pixel_radius_px: float
    adapt_range_sigma: bool
    max_systematic_range_sigma_mm: float
    max_systematic_centroid_sigma_px: float
    reject_outliers: bool
    min_matches: int
    outlier_sigma: float
    outlier_chi2_per_dof: float


class Candidates(NamedTuple):
    """A frame's g candidate reflectors (blobs) as measured and back-projected, what the
    measurement gives §5 (``stages.persistence.kernels.measure.measure_and_back_project``
    returns them, ``stages.pose.kernels.solve.solve_pairs`` takes them; the fields are
    ``stages.pose.solve.Measurements``'): ``uv_px`` (g, 2) centroids (Eq. 19),
    ``range_mm`` (g,) ranges (Eq. 20), ``y_mm`` (g, 3) points in the camera frame (Eq. 8),
    ``weights`` (g,) (Eq. 21), ``sigma_px`` and ``sigma_range_mm`` (g,) their sigmas, and
    ``mixing`` (g, ``stages.extraction.constants.MIX_FIELDS``) their mixing sums (NaN
    rows: none)."""

    uv_px: np.ndarray
    range_mm: np.ndarray
    y_mm: np.ndarray
    weights: np.ndarray
    sigma_px: np.ndarray
    sigma_range_mm: np.ndarray
    mixing: np.ndarray


class GateSettings(NamedTuple):
    """The scalar settings of the blob criteria
    (``stages.extraction.kernels.gates.gate_components``):

    h_min_px (< 0: the range-adaptive window), h_max_px (< 0: none) the paper's size
    window; cos_max_tilt; size_tolerance and size_margin_px of the adaptive window;
    nlog_sigma_px (<= 0: matched to each blob's size); j_peak and j_t, the nLoG
    criteria (fractions of the blob's contrast, or absolute with a fixed sigma);
    background counts; eccentricity_max; i_peak and i_t, the intensity levels; q_max
    the penalty limit."""

    h_min_px: float
    h_max_px: float
    cos_max_tilt: float
    size_tolerance: float
    size_margin_px: float
    nlog_sigma_px: float
    j_peak: float
    j_t: float
    background: float
    eccentricity_max: float
    i_peak: float
    i_t: float
    q_max: float


def camera_record(camera) -> CameraRecord:
    """A ``tofpose.core.camera.CameraModel`` as kernels read it (contiguous float64 arrays)."""
    return CameraRecord(
        fx=float(camera.fx),
        fy=float(camera.fy),
        cx=float(camera.cx),
        cy=float(camera.cy),
        dist=np.ascontiguousarray(camera.dist_array, dtype=np.float64),
        K=np.ascontiguousarray(camera.K, dtype=np.float64),
        pixel_bearings=np.ascontiguousarray(camera.pixel_bearings().reshape(-1, 3)),
        width=int(camera.width),
        height=int(camera.height),
        full_scale_counts=float(camera.full_scale_counts),
    )


def catalog_record(catalog) -> CatalogRecord:
    """A ``tofpose.core.catalog.Catalog`` as kernels read it."""
    return CatalogRecord(
        xyz=np.ascontiguousarray(catalog.positions_mm, dtype=np.float64),
        radii_mm=np.ascontiguousarray(catalog.diameters_mm, dtype=np.float64) / 2,
    )
