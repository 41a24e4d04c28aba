"""The fit's normal equations at one iteration, compiled (``fit._levenberg_marquardt``).

One call does what ``fit`` does in NumPy over (K, P) and (rows, parameters) arrays: the
model's prediction (``model.predict``), the noise model's sigmas (``fit._sigmas``), the
whitened residuals (``fit._residuals``) and the Jacobian (``fit._jacobian``), folded into
the information ``J'J``, the gradient ``J'r`` and the cost ``r'r`` without forming J. A
residual's row is sparse: a pixel touches the pose's six columns, the gain terms of the
discs that reach it, its surround's level and the range offsets, about 20 of the ~60
parameters. ``trial_cost`` is the cost alone at a trial step, with the iteration's
sigmas.

Parameters, in ``fit._Layout``'s order: the pose (a small rotation, rad, then the
translation, mm), per disc its ``GAIN_TERMS`` gain terms, per disc its surround level,
the common range offset (``FitConstants.offset_col``), each disc's own range error
(``FitConstants.disc_col`` on). ``fit`` keeps the NumPy arithmetic as the reference
(``implementation="reference"``); ``tests/.../kernels/test_normal.py`` compares them.
"""

from __future__ import annotations

import math

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.pixelfit.constants import MAD_TO_SIGMA, QUANTISATION_VAR
from tofpose.stages.pixelfit.kernels.derivatives import N_POSE
from tofpose.stages.pixelfit.records import NormalEquations


@jit
def _wrap(x, period):
    return (x + period / 2) % period - period / 2


@jit
def predict(coverage, phasor, plate, state, fit, const):
    """``model.predict`` at the nuisance parameters ``state`` (a ``NuisanceRecord``):
    gray (P,) counts, distance (P,) mm, the mixed phasor (P,) complex, the surround's
    share (P,) and each disc's gain at each pixel (K, P), where the disc reaches it (0
    elsewhere).

    A disc with no coverage of a pixel has there no phasor and no pose derivatives
    either (``kernels.derivatives``: a pixel is covered 0 only when every sub-cell is
    wholly outside), so the loops over the discs skip it: a pixel is reached by one or
    two of the K discs, and the (K, P, 6) derivative arrays are read only there."""
    gains, levels = state.gains, state.levels
    basis, owner = fit.basis, fit.owner
    k_count, p_count = coverage.shape
    n_terms = basis.shape[2]
    g = np.zeros((k_count, p_count))
    gray = np.empty(p_count)
    distance = np.empty(p_count)
    mixed = np.empty(p_count, np.complex128)
    surround = np.empty(p_count)
    for p in range(p_count):
        covered = 0.0
        for k in range(k_count):
            covered += coverage[k, p]
        sur = min(max(1.0 - covered, 0.0), 1.0)
        level = levels[owner[p]] * fit.plate_fraction[p] + fit.beyond_counts[p]
        gray_p = 0.0
        mixed_p = 0.0j
        for k in range(k_count):
            if coverage[k, p] == 0.0:
                continue  # the disc does not reach the pixel: its phasor is 0 too
            gk = 0.0
            for j in range(n_terms):
                gk += basis[k, p, j] * gains[k, j]
            g[k, p] = gk
            gray_p += gk * coverage[k, p]
            mixed_p += gk * phasor[k, p]
        gray[p] = gray_p + level * sur
        mixed[p] = mixed_p + level * sur * plate[p]
        surround[p] = sur
        distance[p] = (
            const.reference_mm
            + const.mm_per_radian * math.atan2(mixed[p].imag, mixed[p].real)
            + state.offset_mm
            + state.disc_offsets_mm[owner[p]]
        )
    return gray, distance, mixed, surround, g


@jit
def sigmas(gray, distance, mixed, fit, const):
    """``fit._sigmas``: gray sigma (P,) counts, distance sigma (P,) mm and the range
    constant k, mm (``const.range_k_mm``, or when NaN the MAD of the distance residuals
    over their noise shape ``sqrt(var) / amplitude``; 1 when that is not positive)."""
    p_count = gray.shape[0]
    sigma_gray = np.empty(p_count)
    shape = np.empty(p_count)
    for p in range(p_count):
        var = max(gray[p], 0.0) + const.extra_var + QUANTISATION_VAR
        amp = max(abs(mixed[p]), 1e-6)
        shape[p] = math.sqrt(var) / amp
        sigma_gray[p] = math.sqrt(var + fit.edge_var_gray[p])
    k = const.range_k_mm
    if math.isnan(k):
        rows = fit.dist_rows
        k = 0.0
        if rows.shape[0] >= 3:
            z = np.empty(rows.shape[0])
            for i in range(rows.shape[0]):
                p = rows[i]
                z[i] = _wrap(fit.distance_mm[p] - distance[p], const.unambiguous_range_mm)
                z[i] /= shape[p]
            k = MAD_TO_SIGMA * np.median(np.abs(z - np.median(z)))
        if not (math.isfinite(k) and k > 0):
            k = 1.0
    sigma_distance = np.empty(p_count)
    for p in range(p_count):
        sd = k * shape[p]
        sigma_distance[p] = math.sqrt(sd * sd + fit.edge_var_distance[p])
    return sigma_gray, sigma_distance, k


@jit
def _gray_residual(p, censored, gray, sigma_gray, fit, const):
    """A gray row's whitened residual and its weight ``-1 / sigma`` (0 for a censored
    pixel whose model is at or above full scale)."""
    s = sigma_gray[p]
    if censored:
        fs = const.full_scale_counts
        return max(fs - gray[p], 0.0) / s, (-1.0 / s if gray[p] < fs else 0.0)
    return (fit.gray[p] - gray[p]) / s, -1.0 / s


@jit
def _cost(gray, distance, state, sigma_gray, sigma_distance, fit, const):
    """``sum r^2`` of ``fit._residuals`` (``state``: a ``NuisanceRecord``)."""
    offset_mm, disc_offsets_mm = state.offset_mm, state.disc_offsets_mm
    cost = 0.0
    for i in range(fit.gray_rows.shape[0]):
        r, _ = _gray_residual(fit.gray_rows[i], False, gray, sigma_gray, fit, const)
        cost += r * r
    for i in range(fit.sat_rows.shape[0]):
        r, _ = _gray_residual(fit.sat_rows[i], True, gray, sigma_gray, fit, const)
        cost += r * r
    for i in range(fit.dist_rows.shape[0]):
        p = fit.dist_rows[i]
        r = _wrap(fit.distance_mm[p] - distance[p], const.unambiguous_range_mm)
        r /= sigma_distance[p]
        cost += r * r
    if const.offset_col >= 0 and math.isfinite(const.offset_sigma_mm):
        r = (offset_mm - const.offset_mean_mm) / const.offset_sigma_mm
        cost += r * r
    if const.disc_col >= 0:
        for k in range(disc_offsets_mm.shape[0]):
            r = disc_offsets_mm[k] / const.disc_range_sigma_mm
            cost += r * r
    return cost


@jit
def _accumulate(cols, vals, n, r, info, grad, free_index, idx, val):
    """Add one row's ``J_i' J_i`` (upper triangle; ``_symmetric`` mirrors it) and ``J_i'
    r_i`` (its ``n`` nonzero entries ``vals`` at ``cols``, in ascending column order, as
    ``normal_equations`` lists them in ``fit._Layout``'s order; ``idx`` and ``val`` are
    scratch of the same length). The fitted columns ``free_index`` keeps ascend with
    them, so the upper triangle is the pairs ``b >= a``. Entries that are exactly 0 are
    skipped: a pixel of the surround beyond every disc's rim has only its level's entry,
    and a gray pixel wholly inside a disc only that disc's gain terms (its pose and level
    entries are 0), so most gray rows are far shorter than their column list."""
    m = 0
    for a in range(n):
        ia = free_index[cols[a]]
        if ia >= 0 and vals[a] != 0.0:  # an exact zero adds nothing to J'J or J'r
            idx[m] = ia
            val[m] = vals[a]
            m += 1
    for a in range(m):
        ia = idx[a]
        va = val[a]
        grad[ia] += va * r
        for b in range(a, m):
            info[ia, idx[b]] += va * val[b]


@jit
def _symmetric(info):
    """Mirror the upper triangle ``_accumulate`` fills into the lower one."""
    for a in range(info.shape[0]):
        for b in range(a):
            info[a, b] = info[b, a]


@jit
def normal_equations(images, state, fit, const, per_disc):
    """The normal equations at a state (a ``NormalEquations``): the information ``J'J``
    (F, F), gradient ``J'r`` (F,) and cost ``r'r`` over the F fitted parameters, with the
    sigmas (gray (P,), distance (P,), k) the iteration uses for its trials too; with
    ``per_disc`` also each disc's rows' share of the information (K, F, F) and of the
    gradient (K, F) (``fit.disc_deletion``; else (0, F, F) and (0, F)).

    images : an ``ImageRecord``, the discs' images at the state's pose and their pose
    derivatives; state : a ``NuisanceRecord``; fit : a ``FitRecord``; const : a
    ``FitConstants``."""
    coverage, phasor, plate = images.coverage, images.phasor, images.plate
    d_coverage, d_phasor, d_plate = images.d_coverage, images.d_phasor, images.d_plate
    levels, offset_mm, disc_offsets_mm = state.levels, state.offset_mm, state.disc_offsets_mm
    gray, distance, mixed, surround, g = predict(coverage, phasor, plate, state, fit, const)
    sigma_gray, sigma_distance, k = sigmas(gray, distance, mixed, fit, const)
    k_count, p_count = coverage.shape
    n_terms = fit.basis.shape[2]
    mpr = const.mm_per_radian
    level_col = N_POSE + n_terms * k_count
    n_free = 0
    for i in range(fit.free_index.shape[0]):
        if fit.free_index[i] >= 0:
            n_free += 1
    info = np.zeros((n_free, n_free))
    grad = np.zeros(n_free)
    n_blocks = k_count if per_disc else 0
    disc_info = np.zeros((n_blocks, n_free, n_free))
    disc_grad = np.zeros((n_blocks, n_free))
    width = N_POSE + n_terms * k_count + 3  # a row's nonzero columns at most
    cols = np.empty(width, np.int64)
    vals = np.empty(width)
    idx = np.empty(width, np.int64)
    val = np.empty(width)
    d_surround = np.empty(N_POSE)
    d_pose = np.empty(N_POSE)
    dm_pose = np.empty(N_POSE, np.complex128)
    n_gray = fit.gray_rows.shape[0]
    for i in range(n_gray + fit.sat_rows.shape[0]):
        censored = i >= n_gray
        p = fit.sat_rows[i - n_gray] if censored else fit.gray_rows[i]
        r, w = _gray_residual(p, censored, gray, sigma_gray, fit, const)
        _surround_derivative(d_coverage, coverage, p, d_surround)
        level = levels[fit.owner[p]] * fit.plate_fraction[p] + fit.beyond_counts[p]
        for e in range(N_POSE):
            d_pose[e] = level * d_surround[e]
        for kk in range(k_count):
            if coverage[kk, p] != 0.0:
                for e in range(N_POSE):
                    d_pose[e] += g[kk, p] * d_coverage[kk, p, e]
        n = 0
        for e in range(N_POSE):
            cols[n] = e
            vals[n] = d_pose[e] * w
            n += 1
        for kk in range(k_count):
            c = coverage[kk, p]
            if c != 0.0:
                for j in range(n_terms):
                    cols[n] = N_POSE + n_terms * kk + j
                    vals[n] = c * fit.basis[kk, p, j] * w
                    n += 1
        cols[n] = level_col + fit.owner[p]
        vals[n] = surround[p] * fit.plate_fraction[p] * w
        n += 1
        _accumulate(cols, vals, n, r, info, grad, fit.free_index, idx, val)
        if per_disc:
            o = fit.owner[p]
            _accumulate(cols, vals, n, r, disc_info[o], disc_grad[o], fit.free_index, idx, val)
    for i in range(fit.dist_rows.shape[0]):
        p = fit.dist_rows[i]
        s = sigma_distance[p]
        r = _wrap(fit.distance_mm[p] - distance[p], const.unambiguous_range_mm) / s
        w = -1.0 / s
        inv = 1.0 / mixed[p] if abs(mixed[p]) > 0 else 1.0 + 0.0j
        _surround_derivative(d_coverage, coverage, p, d_surround)
        level = levels[fit.owner[p]] * fit.plate_fraction[p] + fit.beyond_counts[p]
        for e in range(N_POSE):
            dm_pose[e] = level * (d_surround[e] * plate[p] + surround[p] * d_plate[p, e])
        for kk in range(k_count):
            if coverage[kk, p] != 0.0:
                for e in range(N_POSE):
                    dm_pose[e] += g[kk, p] * d_phasor[kk, p, e]
        n = 0
        for e in range(N_POSE):
            cols[n] = e
            vals[n] = mpr * (dm_pose[e] * inv).imag * w
            n += 1
        for kk in range(k_count):
            ph = phasor[kk, p]
            if ph != 0.0:
                per_gain = mpr * (ph * inv).imag * w
                for j in range(n_terms):
                    cols[n] = N_POSE + n_terms * kk + j
                    vals[n] = per_gain * fit.basis[kk, p, j]
                    n += 1
        cols[n] = level_col + fit.owner[p]
        vals[n] = mpr * (surround[p] * fit.plate_fraction[p] * plate[p] * inv).imag * w
        n += 1
        if const.offset_col >= 0:
            cols[n] = const.offset_col
            vals[n] = w
            n += 1
        if const.disc_col >= 0:
            cols[n] = const.disc_col + fit.owner[p]
            vals[n] = w
            n += 1
        _accumulate(cols, vals, n, r, info, grad, fit.free_index, idx, val)
        if per_disc:
            o = fit.owner[p]
            _accumulate(cols, vals, n, r, disc_info[o], disc_grad[o], fit.free_index, idx, val)
    if const.offset_col >= 0 and math.isfinite(const.offset_sigma_mm):
        cols[0] = const.offset_col
        vals[0] = -1.0 / const.offset_sigma_mm
        r = -(offset_mm - const.offset_mean_mm) / const.offset_sigma_mm
        _accumulate(cols, vals, 1, r, info, grad, fit.free_index, idx, val)
    if const.disc_col >= 0:
        for kk in range(k_count):
            cols[0] = const.disc_col + kk
            vals[0] = -1.0 / const.disc_range_sigma_mm
            r = -disc_offsets_mm[kk] / const.disc_range_sigma_mm
            _accumulate(cols, vals, 1, r, info, grad, fit.free_index, idx, val)
    _symmetric(info)
    for kk in range(n_blocks):
        _symmetric(disc_info[kk])
    cost = _cost(gray, distance, state, sigma_gray, sigma_distance, fit, const)
    return NormalEquations(
        info=info,
        grad=grad,
        cost=cost,
        sigma_gray=sigma_gray,
        sigma_distance=sigma_distance,
        range_k_mm=k,
        disc_info=disc_info,
        disc_grad=disc_grad,
    )


@jit
def _surround_derivative(d_coverage, coverage, p, out):
    """d surround / d pose (6,) at pixel ``p``: minus the discs' coverage derivatives
    where they leave part of the pixel to the surround, else 0 (``predict`` clips it)."""
    covered = 0.0
    for k in range(coverage.shape[0]):
        covered += coverage[k, p]
    for e in range(N_POSE):
        out[e] = 0.0
    if covered < 1.0:
        for k in range(coverage.shape[0]):
            if coverage[k, p] != 0.0:
                for e in range(N_POSE):
                    out[e] -= d_coverage[k, p, e]


@jit
def trial_cost(coverage, phasor, plate, state, sigma_gray, sigma_distance, fit, const):
    """The cost ``r'r`` at a trial state (its discs' images ``coverage``, ``phasor``,
    ``plate``; ``state`` a ``NuisanceRecord``; the rest as ``normal_equations``) with the
    iteration's sigmas."""
    gray, distance, _, _, _ = predict(coverage, phasor, plate, state, fit, const)
    return _cost(gray, distance, state, sigma_gray, sigma_distance, fit, const)
