"""The records the pixel fit's compiled kernel takes (``kernels.images``):
``typing.NamedTuple``s, which numba compiles as tuples with named fields; each is built
by keyword.

Shapes: K discs; P window pixels; S * S sub-cells per pixel."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class DiscRecord(NamedTuple):
    """The discs fitted: ``centres_mm`` (K, 3), target frame; ``radii_mm`` (K,)."""

    centres_mm: np.ndarray
    radii_mm: np.ndarray


class WindowRays(NamedTuple):
    """The window pixels' rays: ``bearings``, ``dbdu``, ``dbdv`` (P, 3), each pixel's
    centre ray and its derivatives over u and v (per px); ``sample_bearings``,
    ``sample_dbdu``, ``sample_dbdv`` (P, S * S, 3), the same for its sub-cells; disc k
    is evaluated at the pixels ``near_index[near_start[k]:near_start[k + 1]]``
    (``near_start`` (K + 1,))."""

    bearings: np.ndarray
    dbdu: np.ndarray
    dbdv: np.ndarray
    sample_bearings: np.ndarray
    sample_dbdu: np.ndarray
    sample_dbdv: np.ndarray
    near_index: np.ndarray
    near_start: np.ndarray


class FitRecord(NamedTuple):
    """What stays fixed over the fit, as the normal equations' kernel takes it
    (``kernels.normal``): the window pixels' ``gray`` (P,) counts and ``distance_mm``
    (P,) (NaN invalid), ``owner`` (P,) the disc whose surround level each sees, the gain
    ``basis`` (K, P, GAIN_TERMS); the residuals' pixels: ``gray_rows`` unsaturated,
    ``sat_rows`` censored, ``dist_rows`` distance (int arrays); ``free_index``
    (n_params,) each parameter's column among the fitted ones, -1 when it is held; the
    pixels' rim variances ``edge_var_gray`` counts^2 and ``edge_var_distance`` mm^2
    (P,) (0 without a rim model error); the surround's parts ``plate_fraction`` (P,) the
    part of each pixel the plate fills and ``beyond_counts`` (P,) the level beyond the
    plate times the rest (``fit._Problem.pixel_levels``)."""

    gray: np.ndarray
    distance_mm: np.ndarray
    owner: np.ndarray
    basis: np.ndarray
    gray_rows: np.ndarray
    sat_rows: np.ndarray
    dist_rows: np.ndarray
    free_index: np.ndarray
    edge_var_gray: np.ndarray
    edge_var_distance: np.ndarray
    plate_fraction: np.ndarray
    beyond_counts: np.ndarray


class FitConstants(NamedTuple):
    """The fit's scalars for ``kernels.normal``: ``mm_per_radian``, ``reference_mm``,
    ``unambiguous_range_mm``, ``full_scale_counts``, ``extra_var`` (counts^2, the gray's
    variance beyond its level), ``range_k_mm`` (NaN: measured on the distance
    residuals), the range offset's column ``offset_col`` (-1: not fitted), its prior's
    ``offset_sigma_mm`` (inf: none) and ``offset_mean_mm``, the first of the discs' own
    range errors' columns ``disc_col`` (-1: not fitted) and their prior's
    ``disc_range_sigma_mm``."""

    mm_per_radian: float
    reference_mm: float
    unambiguous_range_mm: float
    full_scale_counts: float
    extra_var: float
    range_k_mm: float
    offset_col: int
    offset_sigma_mm: float
    offset_mean_mm: float
    disc_col: int
    disc_range_sigma_mm: float


class ImageRecord(NamedTuple):
    """The discs' images at one pose with their pose derivatives, as
    ``kernels.derivatives.disc_images_with_derivatives`` returns them: ``coverage`` (K,
    P), ``phasor`` (K, P) complex, ``plate`` (P,) complex, ``d_coverage`` (K, P, 6),
    ``d_phasor`` (K, P, 6) complex, ``d_plate`` (P, 6) complex."""

    coverage: np.ndarray
    phasor: np.ndarray
    plate: np.ndarray
    d_coverage: np.ndarray
    d_phasor: np.ndarray
    d_plate: np.ndarray


class NuisanceRecord(NamedTuple):
    """The fit's nuisance parameters at a state: ``gains`` (K, GAIN_TERMS) counts,
    ``levels`` (K,) counts, the common range offset ``offset_mm`` and each disc's own
    ``disc_offsets_mm`` (K,)."""

    gains: np.ndarray
    levels: np.ndarray
    offset_mm: float
    disc_offsets_mm: np.ndarray


class NormalEquations(NamedTuple):
    """``kernels.normal.normal_equations``' result over the F fitted parameters: the
    information ``info`` (F, F) = J'J, the gradient ``grad`` (F,) = J'r, the cost ``r'r``,
    the sigmas the iteration used (``sigma_gray`` (P,) counts, ``sigma_distance`` (P,)
    mm, the range constant ``range_k_mm``), and each disc's shares of the information
    ``disc_info`` (K, F, F) and of the gradient ``disc_grad`` (K, F) (empty, K = 0,
    when not asked for)."""

    info: np.ndarray
    grad: np.ndarray
    cost: float
    sigma_gray: np.ndarray
    sigma_distance: np.ndarray
    range_k_mm: float
    disc_info: np.ndarray
    disc_grad: np.ndarray
