"""The discs' pixel-integrated images and their analytic derivatives with respect to the
pose, compiled, in one call (``model.disc_images_with_derivatives``): the pixel fit's
Jacobian at each iteration, where central differences took twelve model evaluations.

The pose is perturbed as the fit steps it: a small rotation ``w`` (rad, left-multiplied,
``R' = exp([w]) R``) then a translation ``dt`` (mm); the six directions are ``w_x, w_y,
w_z, dt_x, dt_y, dt_z``. At ``w = 0`` a disc's centre ``c = R x_k + t`` and normal ``n =
R e_z`` move as ``dc/dw_i = e_i x (c - t)``, ``dn/dw_i = e_i x n``, ``dc/dt_i = e_i``,
``dn/dt_i = 0``. Through ``images._rim_point`` (``model``'s docstring) the chain rule
gives the derivatives of the range to the disc's plane ``lam = (n . c) / (n . b)``, of
the signed distance to the rim ``s = (r - rho) / |g|`` and of the rim normal's
components ``a = |g_u| / |g|``, ``b = |g_v| / |g|``; the sub-cell's coverage
``box_coverage(s, A, B)`` (``A = a h``, ``B = b h``) is differentiated in all three
arguments: the rim normal's turn with the pose moves ``A`` and ``B`` too, and leaving
that term out changes the derivatives by up to 1.2e-3 of their largest (measured at 1-8
m, 0-30 deg: ``tests/.../test_derivatives.py`` fails without it), so it is kept. The
plate's phasor follows its range along the centre ray ``(n . t) / (n . b)``.

Every derivative is exact for the model (the model itself is what approximates the
camera); ``reference.derivatives`` is the same arithmetic in NumPy.
"""

from __future__ import annotations

import math

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.pixelfit.kernels.images import _rim_point

#: the pose's perturbation directions: three small rotations, three translations
N_POSE = 6


@jit
def _ramp(x):
    return x if x > 0.0 else 0.0


@jit
def _r2(x):
    return 0.5 * x * x if x > 0.0 else 0.0


@jit
def _box_coverage_derivatives(s, a, b):
    """``images._box_coverage(s, a, b)`` and its partial derivatives over s, a and b
    (``R2' = max(x, 0)``; 0 beyond the corners, where the coverage is exactly 0 or 1)."""
    if s >= a + b:
        return 1.0, 0.0, 0.0, 0.0
    if s <= -(a + b):
        return 0.0, 0.0, 0.0, 0.0
    pp, pm, mp, mm = s + a + b, s + a - b, s - a + b, s - a - b
    inv = 1.0 / (4.0 * a * b)
    cov = (_r2(pp) - _r2(pm) - _r2(mp) + _r2(mm)) * inv
    d_s = (_ramp(pp) - _ramp(pm) - _ramp(mp) + _ramp(mm)) * inv
    d_a = (_ramp(pp) - _ramp(pm) + _ramp(mp) - _ramp(mm)) * inv - cov / a
    d_b = (_ramp(pp) + _ramp(pm) - _ramp(mp) - _ramp(mm)) * inv - cov / b
    return cov, d_s, d_a, d_b


@jit
def _range_derivative(b, c, n, nb, lam, dc, dn):
    """d lam along one pose direction (``dc``, ``dn`` (3,)): the range ``lam = (n . c) /
    (n . b)`` of ray ``b`` to the disc's plane (``nb`` = n . b); all a wholly covered
    pixel needs."""
    d_nb = b[0] * dn[0] + b[1] * dn[1] + b[2] * dn[2]
    d_nc = dn[0] * c[0] + dn[1] * c[1] + dn[2] * c[2] + n[0] * dc[0] + n[1] * dc[1]
    d_nc += n[2] * dc[2]
    return (d_nc - lam * d_nb) / nb


@jit
def _rim_point_derivatives(b, bu, bv, c, n, radius_mm, dc, dn, out):
    """``images._rim_point`` for one ray (signed distance s px, |g_u|/|g|, |g_v|/|g|,
    range lam mm) and, in ``out`` (4, 6), their derivatives along the six pose
    directions whose centre and normal derivatives are ``dc``, ``dn`` (6, 3)."""
    nb = b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
    lam = (n[0] * c[0] + n[1] * c[1] + n[2] * c[2]) / nb
    bun = bu[0] * n[0] + bu[1] * n[1] + bu[2] * n[2]
    bvn = bv[0] * n[0] + bv[1] * n[1] + bv[2] * n[2]
    cu = -lam * bun / nb
    cv = -lam * bvn / nb
    d = (lam * b[0] - c[0], lam * b[1] - c[1], lam * b[2] - c[2])
    qu = (cu * b[0] + lam * bu[0], cu * b[1] + lam * bu[1], cu * b[2] + lam * bu[2])
    qv = (cv * b[0] + lam * bv[0], cv * b[1] + lam * bv[1], cv * b[2] + lam * bv[2])
    rho2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
    su = d[0] * qu[0] + d[1] * qu[1] + d[2] * qu[2]
    sv = d[0] * qv[0] + d[1] * qv[1] + d[2] * qv[2]
    rho = max(math.sqrt(rho2), 1e-12)
    gu = su / rho
    gv = sv / rho
    gn = max(math.hypot(gu, gv), 1e-12)
    s = (radius_mm - rho) / gn
    au = abs(gu) / gn
    av = abs(gv) / gn
    sign_u = 1.0 if gu >= 0.0 else -1.0
    sign_v = 1.0 if gv >= 0.0 else -1.0
    for j in range(N_POSE):
        d_nb = b[0] * dn[j, 0] + b[1] * dn[j, 1] + b[2] * dn[j, 2]
        d_nc = dn[j, 0] * c[0] + dn[j, 1] * c[1] + dn[j, 2] * c[2]
        d_nc += n[0] * dc[j, 0] + n[1] * dc[j, 1] + n[2] * dc[j, 2]
        d_lam = (d_nc - lam * d_nb) / nb
        d_bun = bu[0] * dn[j, 0] + bu[1] * dn[j, 1] + bu[2] * dn[j, 2]
        d_bvn = bv[0] * dn[j, 0] + bv[1] * dn[j, 1] + bv[2] * dn[j, 2]
        d_cu = -(d_lam * bun + lam * d_bun) / nb + lam * bun * d_nb / (nb * nb)
        d_cv = -(d_lam * bvn + lam * d_bvn) / nb + lam * bvn * d_nb / (nb * nb)
        d_rho_num = 0.0
        d_su = 0.0
        d_sv = 0.0
        for i in range(3):
            dd = d_lam * b[i] - dc[j, i]
            dqu = d_cu * b[i] + d_lam * bu[i]
            dqv = d_cv * b[i] + d_lam * bv[i]
            d_rho_num += d[i] * dd
            d_su += dd * qu[i] + d[i] * dqu
            d_sv += dd * qv[i] + d[i] * dqv
        d_rho = d_rho_num / rho
        d_gu = (d_su - gu * d_rho) / rho
        d_gv = (d_sv - gv * d_rho) / rho
        d_gn = (gu * d_gu + gv * d_gv) / gn
        out[0, j] = (-d_rho - s * d_gn) / gn
        out[1, j] = (sign_u * d_gu - au * d_gn) / gn
        out[2, j] = (sign_v * d_gv - av * d_gn) / gn
        out[3, j] = d_lam
    return s, au, av, lam


@jit
def _cross_axis(i, v, out):
    """``out = e_i x v`` (3,)."""
    if i == 0:
        out[0], out[1], out[2] = 0.0, -v[2], v[1]
    elif i == 1:
        out[0], out[1], out[2] = v[2], 0.0, -v[0]
    else:
        out[0], out[1], out[2] = -v[1], v[0], 0.0


@jit
def _pose_directions(R, centre_mm, n, dc, dn):
    """The disc's centre and normal derivatives ``dc``, ``dn`` (6, 3) along the pose
    directions (module docstring); ``centre_mm`` (3,) on the target, ``n`` = R e_z."""
    m = np.empty(3)
    for i in range(3):
        m[i] = R[i, 0] * centre_mm[0] + R[i, 1] * centre_mm[1] + R[i, 2] * centre_mm[2]
    for i in range(3):
        _cross_axis(i, m, dc[i])
        _cross_axis(i, n, dn[i])
        for e in range(3):
            dc[3 + i, e] = 1.0 if e == i else 0.0
            dn[3 + i, e] = 0.0


@jit
def _plate(R, t_mm, bearings, mm_per_radian, reference_mm):
    """The plate's unit phasor (P,) complex along the centre rays and its derivative
    (P, 6) over the pose: range ``(n . t) / (n . b)``, n = R e_z."""
    p_count = bearings.shape[0]
    plate = np.empty(p_count, np.complex128)
    d_plate = np.empty((p_count, N_POSE), np.complex128)
    n = np.ascontiguousarray(R[:, 2])
    dn = np.empty((3, 3))
    for i in range(3):
        _cross_axis(i, n, dn[i])
    nt = n[0] * t_mm[0] + n[1] * t_mm[1] + n[2] * t_mm[2]
    for p in range(p_count):
        b = bearings[p]
        nb = b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
        plate_range = nt / nb
        phase = (plate_range - reference_mm) / mm_per_radian
        ph = complex(math.cos(phase), math.sin(phase))
        plate[p] = ph
        for j in range(N_POSE):
            if j < 3:
                d_nt = dn[j, 0] * t_mm[0] + dn[j, 1] * t_mm[1] + dn[j, 2] * t_mm[2]
                d_nb = b[0] * dn[j, 0] + b[1] * dn[j, 1] + b[2] * dn[j, 2]
                d_range = (d_nt - plate_range * d_nb) / nb
            else:
                d_range = n[j - 3] / nb
            d_plate[p, j] = 1j * (d_range / mm_per_radian) * ph
    return plate, d_plate


@jit
def disc_images_with_derivatives(R, t_mm, discs, rays, band_px, mm_per_radian, reference_mm):
    """The discs' images at the pose ``(R, t_mm)`` with their pose derivatives
    (arguments as ``images.disc_images``):

    coverage (K, P), phasor (K, P) complex, plate (P,) complex (``model.DiscImages``);
    d_coverage (K, P, 6), d_phasor (K, P, 6) complex, d_plate (P, 6) complex: per rad of
    the rotation ``w`` (the first three) and per mm of the translation (the last three).
    """
    centres_mm, radii_mm = discs.centres_mm, discs.radii_mm
    bearings, dbdu, dbdv = rays.bearings, rays.dbdu, rays.dbdv
    sample_bearings, sample_dbdu, sample_dbdv = (
        rays.sample_bearings,
        rays.sample_dbdu,
        rays.sample_dbdv,
    )
    near_index, near_start = rays.near_index, rays.near_start
    k_count = centres_mm.shape[0]
    p_count = bearings.shape[0]
    n_sub = sample_bearings.shape[1]
    subsamples = int(round(math.sqrt(n_sub)))
    half = 0.5 / subsamples
    floor = 1e-4 * half
    coverage = np.zeros((k_count, p_count))
    phasor = np.zeros((k_count, p_count), np.complex128)
    d_coverage = np.zeros((k_count, p_count, N_POSE))
    d_phasor = np.zeros((k_count, p_count, N_POSE), np.complex128)
    plate, d_plate = _plate(R, t_mm, bearings, mm_per_radian, reference_mm)
    n = np.ascontiguousarray(R[:, 2])
    c = np.empty(3)
    dc = np.empty((N_POSE, 3))
    dn = np.empty((N_POSE, 3))
    out = np.empty((4, N_POSE))
    d_cov_sum = np.empty(N_POSE)
    d_re_sum = np.empty(N_POSE)
    d_im_sum = np.empty(N_POSE)
    for k in range(k_count):
        for i in range(3):
            c[i] = R[i, 0] * centres_mm[k, 0] + R[i, 1] * centres_mm[k, 1]
            c[i] += R[i, 2] * centres_mm[k, 2] + t_mm[i]
        _pose_directions(R, centres_mm[k], n, dc, dn)
        r = radii_mm[k]
        for j in range(near_start[k], near_start[k + 1]):
            p = near_index[j]
            s, _, _, lam = _rim_point(bearings[p], dbdu[p], dbdv[p], c, n, r)
            if s >= band_px:
                phase = (lam - reference_mm) / mm_per_radian
                ph = complex(math.cos(phase), math.sin(phase))
                coverage[k, p] = 1.0
                phasor[k, p] = ph
                b = bearings[p]
                nb = b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
                for e in range(N_POSE):
                    d_phasor[k, p, e] = (
                        1j
                        * (_range_derivative(b, c, n, nb, lam, dc[e], dn[e]) / mm_per_radian)
                        * ph
                    )
            elif abs(s) < band_px:
                cov_sum = 0.0
                re_sum = 0.0
                im_sum = 0.0
                d_cov_sum[:] = 0.0
                d_re_sum[:] = 0.0
                d_im_sum[:] = 0.0
                for q in range(n_sub):
                    sb, sbu, sbv = sample_bearings[p, q], sample_dbdu[p, q], sample_dbdv[p, q]
                    ss, au, av, lam_s = _rim_point(sb, sbu, sbv, c, n, r)
                    a_half = au * half
                    b_half = av * half
                    reach = max(a_half, floor) + max(b_half, floor)
                    if ss <= -reach:
                        continue  # wholly outside: coverage and derivatives 0
                    if ss >= reach:
                        # wholly inside: coverage 1, its derivatives 0; only the phase
                        # moves, with the range to the plane (the rim's chain rule is
                        # not needed: ``_box_coverage_derivatives`` is 1, 0, 0, 0 here)
                        phase = (lam_s - reference_mm) / mm_per_radian
                        cos_p = math.cos(phase)
                        sin_p = math.sin(phase)
                        cov_sum += 1.0
                        re_sum += cos_p
                        im_sum += sin_p
                        nb_s = sb[0] * n[0] + sb[1] * n[1] + sb[2] * n[2]
                        for e in range(N_POSE):
                            d_phase = _range_derivative(sb, c, n, nb_s, lam_s, dc[e], dn[e])
                            d_phase /= mm_per_radian
                            d_re_sum[e] -= d_phase * sin_p
                            d_im_sum[e] += d_phase * cos_p
                        continue
                    _rim_point_derivatives(sb, sbu, sbv, c, n, r, dc, dn, out)
                    cov_s, c_s, c_a, c_b = _box_coverage_derivatives(
                        ss, max(a_half, floor), max(b_half, floor)
                    )
                    phase = (lam_s - reference_mm) / mm_per_radian
                    cos_p = math.cos(phase)
                    sin_p = math.sin(phase)
                    cov_sum += cov_s
                    re_sum += cov_s * cos_p
                    im_sum += cov_s * sin_p
                    for e in range(N_POSE):
                        d_cov = c_s * out[0, e]
                        if a_half > floor:
                            d_cov += c_a * half * out[1, e]
                        if b_half > floor:
                            d_cov += c_b * half * out[2, e]
                        d_phase = cov_s * out[3, e] / mm_per_radian
                        d_cov_sum[e] += d_cov
                        d_re_sum[e] += d_cov * cos_p - d_phase * sin_p
                        d_im_sum[e] += d_cov * sin_p + d_phase * cos_p
                coverage[k, p] = cov_sum / n_sub
                phasor[k, p] = complex(re_sum, im_sum) / n_sub
                for e in range(N_POSE):
                    d_coverage[k, p, e] = d_cov_sum[e] / n_sub
                    d_phasor[k, p, e] = complex(d_re_sum[e], d_im_sum[e]) / n_sub
    return coverage, phasor, plate, d_coverage, d_phasor, d_plate
