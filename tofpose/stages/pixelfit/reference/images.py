"""The discs' pixel-integrated images in NumPy (``model.disc_images`` with
``compiled=False``): the statement the compiled kernel (``kernels.images``) is tested
against, one NumPy operation per disc over its pixels (``model``'s docstring gives the
geometry)."""

from __future__ import annotations

import numpy as np

from tofpose.stages.pixelfit.records import DiscRecord, WindowRays


def box_coverage(s: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Area fraction of the square ``|x| <= hx, |y| <= hy`` inside the half-plane
    ``g . x <= s`` (unit normal g), with ``a = |g_x| hx`` and ``b = |g_y| hy``: the box
    integral ``[R2(s + a + b) - R2(s + a - b) - R2(s - a + b) + R2(s - a - b)] / (4 a b)``,
    ``R2(x) = max(x, 0)^2 / 2``. All arrays broadcast; ``a, b > 0``."""

    def r2(x):
        return 0.5 * np.maximum(x, 0.0) ** 2

    area = (r2(s + a + b) - r2(s + a - b) - r2(s - a + b) + r2(s - a - b)) / (4.0 * a * b)
    # beyond the corners exactly 1 or 0 (no cancellation of large squares)
    return np.where(s >= a + b, 1.0, np.where(s <= -(a + b), 0.0, area))


def _rim_geometry(
    b: np.ndarray,
    bu: np.ndarray,
    bv: np.ndarray,
    c: np.ndarray,
    n: np.ndarray,
    radius_mm: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For rays ``b`` (..., 3) with derivatives ``bu, bv``: the signed distance to the
    disc's rim (px, positive inside), the outward normal's |u| and |v| components, and
    the range to the disc's plane (mm)."""
    nb = b @ n
    lam = (n @ c) / nb
    d = lam[..., None] * b - c
    rho = np.maximum(np.linalg.norm(d, axis=-1), 1e-12)
    # d lam / du = -lam (n . b_u) / (n . b); d q / du = lam_u b + lam b_u
    qu = (-lam * (bu @ n) / nb)[..., None] * b + lam[..., None] * bu
    qv = (-lam * (bv @ n) / nb)[..., None] * b + lam[..., None] * bv
    gu = np.sum(d * qu, axis=-1) / rho
    gv = np.sum(d * qv, axis=-1) / rho
    gn = np.maximum(np.hypot(gu, gv), 1e-12)
    return (radius_mm - rho) / gn, np.abs(gu) / gn, np.abs(gv) / gn, lam


def disc_images(
    R: np.ndarray,
    t_mm: np.ndarray,
    discs: DiscRecord,
    rays: WindowRays,
    band_px: float,
    mm_per_radian: float,
    reference_mm: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Coverage (K, P) and unit-gain phasor (K, P) complex of K discs over P window pixels
    at the pose ``(R, t_mm)``, as ``kernels.images.disc_images`` (same arguments)."""
    k_count, p_count = len(discs.radii_mm), len(rays.bearings)
    coverage = np.zeros((k_count, p_count))
    phasor = np.zeros((k_count, p_count), complex)
    subsamples = int(round(np.sqrt(rays.sample_bearings.shape[1])))
    half = 0.5 / subsamples
    floor = 1e-4 * half  # an axis-aligned rim: the box integral's limit, kept finite
    n = R[:, 2]
    for k in range(k_count):
        idx = rays.near_index[rays.near_start[k] : rays.near_start[k + 1]]
        if not len(idx):
            continue
        c = R @ discs.centres_mm[k] + t_mm
        r = discs.radii_mm[k]
        s, _, _, lam = _rim_geometry(rays.bearings[idx], rays.dbdu[idx], rays.dbdv[idx], c, n, r)
        inside = s >= band_px
        band = np.abs(s) < band_px
        coverage[k, idx[inside]] = 1.0
        phasor[k, idx[inside]] = np.exp(1j * (lam[inside] - reference_mm) / mm_per_radian)
        if band.any():
            j = idx[band]
            ss, au, av, lam_s = _rim_geometry(
                rays.sample_bearings[j], rays.sample_dbdu[j], rays.sample_dbdv[j], c, n, r
            )
            cov_s = box_coverage(ss, np.maximum(au * half, floor), np.maximum(av * half, floor))
            coverage[k, j] = cov_s.mean(axis=1)
            phase = np.exp(1j * (lam_s - reference_mm) / mm_per_radian)
            phasor[k, j] = np.mean(cov_s * phase, axis=1)
    return coverage, phasor
