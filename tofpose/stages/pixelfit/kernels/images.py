"""The discs' pixel-integrated images (``model.disc_images``), compiled: one call per
pose instead of a dozen NumPy operations per disc. The fit's trial steps use it;
``derivatives`` adds the pose derivatives for the Jacobian (dearer, so not paid on a
trial)."""

from __future__ import annotations

import math

import numpy as np

from tofpose.core.compiled import jit


@jit
def _rim_point(b, bu, bv, c, n, radius_mm):
    """``model._rim_geometry`` for one ray: (signed distance to the rim px, |g_u|, |g_v|
    of the outward normal, range to the disc's plane mm)."""
    nb = b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
    lam = (n[0] * c[0] + n[1] * c[1] + n[2] * c[2]) / nb
    bun = bu[0] * n[0] + bu[1] * n[1] + bu[2] * n[2]
    bvn = bv[0] * n[0] + bv[1] * n[1] + bv[2] * n[2]
    rho2 = 0.0
    dqu = 0.0
    dqv = 0.0
    for i in range(3):
        d = lam * b[i] - c[i]
        qu = (-lam * bun / nb) * b[i] + lam * bu[i]
        qv = (-lam * bvn / nb) * b[i] + lam * bv[i]
        rho2 += d * d
        dqu += d * qu
        dqv += d * qv
    rho = max(math.sqrt(rho2), 1e-12)
    gu = dqu / rho
    gv = dqv / rho
    gn = max(math.hypot(gu, gv), 1e-12)
    return (radius_mm - rho) / gn, abs(gu) / gn, abs(gv) / gn, lam


@jit
def _r2(x):
    return 0.5 * x * x if x > 0.0 else 0.0


@jit
def _box_coverage(s, a, b):
    """``model.box_coverage`` for one sub-cell."""
    if s >= a + b:
        return 1.0
    if s <= -(a + b):
        return 0.0
    return (_r2(s + a + b) - _r2(s + a - b) - _r2(s - a + b) + _r2(s - a - b)) / (4.0 * a * b)


@jit
def disc_images(R, t_mm, discs, rays, band_px, mm_per_radian, reference_mm):
    """Coverage (K, P) and unit-gain phasor (K, P) complex of K discs over P window pixels
    at the pose ``(R, t_mm)`` (``model.disc_images``' arithmetic).

    discs : a ``records.DiscRecord`` (the discs on the target); rays : a
    ``records.WindowRays`` (the pixels' and sub-cells' rays, and which pixels each disc
    is evaluated at); ``band_px``: a pixel whose centre is further than this from the
    rim is wholly inside or outside.
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
    n = np.ascontiguousarray(R[:, 2])
    c = np.empty(3)
    for k in range(k_count):
        for i in range(3):
            c[i] = R[i, 0] * centres_mm[k, 0] + R[i, 1] * centres_mm[k, 1]
            c[i] += R[i, 2] * centres_mm[k, 2] + t_mm[i]
        r = radii_mm[k]
        for j in range(near_start[k], near_start[k + 1]):
            p = near_index[j]
            s, _, _, lam = _rim_point(bearings[p], dbdu[p], dbdv[p], c, n, r)
            if s >= band_px:
                phase = (lam - reference_mm) / mm_per_radian
                coverage[k, p] = 1.0
                phasor[k, p] = complex(math.cos(phase), math.sin(phase))
            elif abs(s) < band_px:
                cov_sum = 0.0
                re_sum = 0.0
                im_sum = 0.0
                for q in range(n_sub):
                    ss, au, av, lam_s = _rim_point(
                        sample_bearings[p, q], sample_dbdu[p, q], sample_dbdv[p, q], c, n, r
                    )
                    cov_s = _box_coverage(ss, max(au * half, floor), max(av * half, floor))
                    if cov_s > 0.0:
                        phase = (lam_s - reference_mm) / mm_per_radian
                        cov_sum += cov_s
                        re_sum += cov_s * math.cos(phase)
                        im_sum += cov_s * math.sin(phase)
                coverage[k, p] = cov_sum / n_sub
                phasor[k, p] = complex(re_sum, im_sum) / n_sub
    return coverage, phasor
