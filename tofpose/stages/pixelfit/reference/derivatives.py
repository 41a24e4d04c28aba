"""The discs' images and their analytic pose derivatives in NumPy
(``model.disc_images_with_derivatives`` with ``compiled=False``): the statement the
compiled kernel (``kernels.derivatives``, whose docstring gives the chain rule) is tested
against, one NumPy operation per disc over its pixels."""

from __future__ import annotations

import numpy as np

from tofpose.stages.pixelfit.records import DiscRecord, WindowRays
from tofpose.stages.pixelfit.reference.images import box_coverage

#: the pose's perturbation directions: three small rotations (rad), three translations (mm)
N_POSE = 6


def box_coverage_derivatives(
    s: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``box_coverage(s, a, b)`` and its partial derivatives over s, a and b (all
    broadcast; 0 beyond the corners, where the coverage is exactly 0 or 1)."""

    def ramp(x):
        return np.maximum(x, 0.0)

    pp, pm, mp, mm = s + a + b, s + a - b, s - a + b, s - a - b
    inv = 1.0 / (4.0 * a * b)
    cov = box_coverage(s, a, b)
    d_s = (ramp(pp) - ramp(pm) - ramp(mp) + ramp(mm)) * inv
    d_a = (ramp(pp) - ramp(pm) + ramp(mp) - ramp(mm)) * inv - cov / a
    d_b = (ramp(pp) + ramp(pm) - ramp(mp) - ramp(mm)) * inv - cov / b
    corner = (s >= a + b) | (s <= -(a + b))
    zero = np.zeros_like(d_s)
    return (
        cov,
        np.where(corner, zero, d_s),
        np.where(corner, zero, d_a),
        np.where(corner, zero, d_b),
    )


def pose_directions(R: np.ndarray, centre_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A disc's centre and normal derivatives (6, 3) each along the pose directions:
    ``e_i x (R x)`` and ``e_i x n`` for the rotations, ``e_i`` and 0 for the
    translations."""
    m = R @ centre_mm
    n = R[:, 2]
    eye = np.eye(3)
    dc = np.concatenate([np.cross(eye, m), eye])
    dn = np.concatenate([np.cross(eye, n), np.zeros((3, 3))])
    return dc, dn


def rim_geometry_derivatives(
    b: np.ndarray,
    bu: np.ndarray,
    bv: np.ndarray,
    c: np.ndarray,
    n: np.ndarray,
    radius_mm: float,
    dc: np.ndarray,
    dn: np.ndarray,
) -> tuple[np.ndarray, ...]:
    """``images._rim_geometry`` for rays ``b`` (..., 3) (signed distance s, |g_u|/|g|,
    |g_v|/|g|, range lam, each (...)) and their derivatives (..., 6) along the pose
    directions with centre and normal derivatives ``dc``, ``dn`` (6, 3)."""
    nb = b @ n
    lam = (n @ c) / nb
    bun, bvn = bu @ n, bv @ n
    cu, cv = -lam * bun / nb, -lam * bvn / nb
    d = lam[..., None] * b - c
    qu = cu[..., None] * b + lam[..., None] * bu
    qv = cv[..., None] * b + lam[..., None] * bv
    rho = np.maximum(np.linalg.norm(d, axis=-1), 1e-12)
    gu = np.sum(d * qu, axis=-1) / rho
    gv = np.sum(d * qv, axis=-1) / rho
    gn = np.maximum(np.hypot(gu, gv), 1e-12)
    s = (radius_mm - rho) / gn
    au, av = np.abs(gu) / gn, np.abs(gv) / gn
    # derivatives along the six directions: trailing axis
    d_nb = b @ dn.T  # (..., 6)
    d_nc = dn @ c + dc @ n  # (6,)
    d_lam = (d_nc - lam[..., None] * d_nb) / nb[..., None]
    d_bun, d_bvn = bu @ dn.T, bv @ dn.T
    x = lam[..., None]
    nb6 = nb[..., None]
    d_cu = -(d_lam * bun[..., None] + x * d_bun) / nb6 + (x * bun[..., None] * d_nb) / nb6**2
    d_cv = -(d_lam * bvn[..., None] + x * d_bvn) / nb6 + (x * bvn[..., None] * d_nb) / nb6**2
    # (..., 6, 3)
    dd = d_lam[..., None] * b[..., None, :] - dc
    dqu = d_cu[..., None] * b[..., None, :] + d_lam[..., None] * bu[..., None, :]
    dqv = d_cv[..., None] * b[..., None, :] + d_lam[..., None] * bv[..., None, :]
    d_rho = np.sum(d[..., None, :] * dd, axis=-1) / rho[..., None]
    d_su = np.sum(dd * qu[..., None, :] + d[..., None, :] * dqu, axis=-1)
    d_sv = np.sum(dd * qv[..., None, :] + d[..., None, :] * dqv, axis=-1)
    gu6, gv6, gn6, rho6 = gu[..., None], gv[..., None], gn[..., None], rho[..., None]
    d_gu = (d_su - gu6 * d_rho) / rho6
    d_gv = (d_sv - gv6 * d_rho) / rho6
    d_gn = (gu6 * d_gu + gv6 * d_gv) / gn6
    d_s = (-d_rho - s[..., None] * d_gn) / gn6
    sign_u = np.where(gu >= 0.0, 1.0, -1.0)[..., None]
    sign_v = np.where(gv >= 0.0, 1.0, -1.0)[..., None]
    d_au = (sign_u * d_gu - au[..., None] * d_gn) / gn6
    d_av = (sign_v * d_gv - av[..., None] * d_gn) / gn6
    return s, au, av, lam, d_s, d_au, d_av, d_lam


def plate_with_derivatives(
    R: np.ndarray,
    t_mm: np.ndarray,
    bearings: np.ndarray,
    mm_per_radian: float,
    reference_mm: float,
) -> tuple[np.ndarray, np.ndarray]:
    """The plate's unit phasor (P,) complex along the centre rays ``bearings`` (P, 3) and
    its derivative (P, 6): range ``(n . t) / (n . b)``, n = R e_z."""
    n = R[:, 2]
    nb = bearings @ n
    plate_range = (n @ t_mm) / nb
    plate = np.exp(1j * (plate_range - reference_mm) / mm_per_radian)
    dn = np.cross(np.eye(3), n)  # (3, 3)
    d_rot = (dn @ t_mm - plate_range[:, None] * (bearings @ dn.T)) / nb[:, None]
    d_range = np.concatenate([d_rot, n[None, :] / nb[:, None]], axis=1)
    return plate, 1j * (d_range / mm_per_radian) * plate[:, None]


def disc_images_with_derivatives(
    R: np.ndarray,
    t_mm: np.ndarray,
    discs: DiscRecord,
    rays: WindowRays,
    band_px: float,
    mm_per_radian: float,
    reference_mm: float,
) -> tuple[np.ndarray, ...]:
    """As ``kernels.derivatives.disc_images_with_derivatives`` (same arguments): coverage
    (K, P), phasor (K, P) complex, plate (P,) complex, d_coverage (K, P, 6), d_phasor
    (K, P, 6) complex, d_plate (P, 6) complex."""
    k_count, p_count = len(discs.radii_mm), len(rays.bearings)
    coverage = np.zeros((k_count, p_count))
    phasor = np.zeros((k_count, p_count), complex)
    d_coverage = np.zeros((k_count, p_count, N_POSE))
    d_phasor = np.zeros((k_count, p_count, N_POSE), complex)
    plate, d_plate = plate_with_derivatives(R, t_mm, rays.bearings, mm_per_radian, reference_mm)
    subsamples = int(round(np.sqrt(rays.sample_bearings.shape[1])))
    half = 0.5 / subsamples
    floor = 1e-4 * half  # an axis-aligned rim: the box integral's limit, kept finite
    n = R[:, 2]
    for k in range(k_count):
        idx = rays.near_index[rays.near_start[k] : rays.near_start[k + 1]]
        if not len(idx):
            continue
        c = R @ discs.centres_mm[k] + t_mm
        dc, dn = pose_directions(R, discs.centres_mm[k])
        r = discs.radii_mm[k]
        s, _, _, lam, _, _, _, d_lam = rim_geometry_derivatives(
            rays.bearings[idx], rays.dbdu[idx], rays.dbdv[idx], c, n, r, dc, dn
        )
        inside = s >= band_px
        band = np.abs(s) < band_px
        j = idx[inside]
        ph = np.exp(1j * (lam[inside] - reference_mm) / mm_per_radian)
        coverage[k, j] = 1.0
        phasor[k, j] = ph
        d_phasor[k, j] = 1j * (d_lam[inside] / mm_per_radian) * ph[:, None]
        if not band.any():
            continue
        j = idx[band]
        ss, au, av, lam_s, d_ss, d_au, d_av, d_lam_s = rim_geometry_derivatives(
            rays.sample_bearings[j], rays.sample_dbdu[j], rays.sample_dbdv[j], c, n, r, dc, dn
        )
        a_half, b_half = au * half, av * half
        cov_s, c_s, c_a, c_b = box_coverage_derivatives(
            ss, np.maximum(a_half, floor), np.maximum(b_half, floor)
        )
        # (pixels, sub-cells, 6); a clamped half-width does not move with the pose
        d_cov_s = (
            c_s[..., None] * d_ss
            + np.where(a_half > floor, c_a * half, 0.0)[..., None] * d_au
            + np.where(b_half > floor, c_b * half, 0.0)[..., None] * d_av
        )
        ph_s = np.exp(1j * (lam_s - reference_mm) / mm_per_radian)
        coverage[k, j] = cov_s.mean(axis=1)
        phasor[k, j] = np.mean(cov_s * ph_s, axis=1)
        d_coverage[k, j] = d_cov_s.mean(axis=1)
        d_ph = (d_cov_s + 1j * cov_s[..., None] * d_lam_s / mm_per_radian) * ph_s[..., None]
        d_phasor[k, j] = d_ph.mean(axis=1)
    return coverage, phasor, plate, d_coverage, d_phasor, d_plate
