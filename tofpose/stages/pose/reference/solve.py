"""§5 from matched pairs as the pipeline runs it
(``tofpose.stages.pose.kernels.solve.solve_pairs``),
stated in NumPy: the weighted SVD (Eqs. 40-50) of the matched points, completion with
unmatched blobs and the SVD again, the mixing model's ranges for small discs, the
perspective bias of the discs' image centres (§3.3) taken off the centroids, the
bearings (Eq. 9) and points (Eq. 8), and the fit with its outlier step
(``pose.fit_with_outliers``).

Shapes: g candidates (blobs), m matched pairs, N catalog reflectors. ``candidates``,
``catalog`` and ``camera`` are read by field name (``core.records.Candidates``;
``CatalogRecord``: xyz, radii_mm; ``CameraRecord``: K, fx, dist), ``fit`` and
``offset_prior`` as in ``pose.fit_with_outliers``.
"""

from __future__ import annotations

import numpy as np

from tofpose.core.reference.camera import bearings
from tofpose.stages.extraction.reference.mixed_pixels import unmixed_range
from tofpose.stages.pose.records import Reflectors, SolvedPairs
from tofpose.stages.pose.reference.pose import absolute_orientation, fit_with_outliers


def disc_centre_offsets(K, centres, normal, radii) -> np.ndarray:
    """(m, 2) px: the centre of each disc's image ellipse minus the image of its centre
    (§3.3's projected-circle bias), for discs of radii (m,) mm centred at ``centres``
    (m, 3) mm (camera frame) with the shared normal (3,) (any length). With in-plane unit
    axes a, b (a = n x (1, 0, 0), or n x (0, 1, 0) when n is within ~26 deg of the x axis;
    b = n x a) and H = K [a b c], the image conic is Q = H^-T diag(1, 1, -r^2) H^-1 and its
    centre -Q[:2, :2]^-1 Q[:2, 2]; the projected centre is K c. Distortion is left out."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.cross(n, [1.0, 0.0, 0.0] if abs(n[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    b = np.cross(n, a)
    out = np.empty((len(centres), 2))
    for i, (c, r) in enumerate(zip(np.asarray(centres, float), radii, strict=True)):
        H_inv = np.linalg.inv(K @ np.column_stack((a, b, c)))
        Q = H_inv.T @ np.diag([1.0, 1.0, -(r**2)]) @ H_inv
        p = K @ c
        out[i] = -np.linalg.solve(Q[:2, :2], Q[:2, 2]) - p[:2] / p[2]
    return out


def complete_pairs(y, k_idx, i_idx, xyz, R, t, tol_mm):
    """Completion (ours): pair unmatched blobs (rows of y (g, 3), the observed points)
    with unmatched reflectors (rows of xyz (N, 3)) predicted by the pose (R, t): while
    the closest remaining pair is nearer than ``tol_mm``, add it (the first in the
    order (blob, reflector) among equals) and use up its blob and reflector. k_idx,
    i_idx (m,): the matched (blob, reflector) pairs. Returns them extended (int)."""
    free_k = np.setdiff1d(np.arange(len(y)), k_idx)
    free_i = np.setdiff1d(np.arange(len(xyz)), i_idx)
    ks, is_ = list(k_idx), list(i_idx)
    predicted = xyz[free_i] @ R.T + t
    dist = np.linalg.norm(y[free_k][:, None, :] - predicted[None, :, :], axis=-1)
    while dist.size and dist.min() < tol_mm:
        a, b = np.unravel_index(np.argmin(dist), dist.shape)
        ks.append(free_k[a])
        is_.append(free_i[b])
        dist[a, :] = np.inf
        dist[:, b] = np.inf
    return np.array(ks, np.int64), np.array(is_, np.int64)


def solve_pairs(candidates, k_idx, i_idx, catalog, camera, fit, complete_tol_mm, offset_prior):
    """The pose of matched pairs (§5 as the pipeline runs it):

    1. the weighted absolute orientation (Eqs. 40-50) of the pairs' points y[k] (Eq. 8)
       with weights w[k] (Eq. 21) to the catalog points xyz[i];
    2. (``complete_tol_mm`` > 0) ``complete_pairs`` at that pose, and when it added
       pairs the absolute orientation of them all;
    3. (``fit.mixed_pixel_radius_px`` > 0) the range of each matched disc from its mixing
       sums (``mixed_pixels.unmixed_range``: apparent radius r fx / rho, the incidence
       |R e_z . c| / |c| at its centre c = R x + t of that pose), its range sigma
       widened in quadrature by the model's sensitivity;
    4. (``fit.correct_perspective_bias``) the centroids less ``disc_centre_offsets`` at
       those centres with the plate's normal R e_z;
    5. bearings e (Eq. 9) of the centroids, bearing sigmas sigma_px / fx, and
       ``pose.fit_with_outliers`` of those reflectors with the bearing cap
       ``fit.max_systematic_centroid_sigma_px / fx``.

    candidates : the candidates' centroids, ranges, points, weights, sigmas and mixing
    sums (a ``core.records.Candidates``, read by field name; mixing (g, 6), NaN rows:
    none); k_idx, i_idx (m,): the matched (candidate, catalog) pairs. Returns the
    ``SolvedPairs``: k_idx, i_idx (m',) after completion, uv (m', 2), the observed
    ``Reflectors`` (x, e, rho, sr, sb) and ``fit_with_outliers``' ``OutlierFit``. The
    offset is not taken out of the observed ranges."""
    xyz, radii = np.asarray(catalog.xyz, float), np.asarray(catalog.radii_mm, float)
    y, w = candidates.y_mm, candidates.weights
    R, t = absolute_orientation(xyz[i_idx], y[k_idx], w[k_idx])
    if complete_tol_mm > 0:
        n = len(k_idx)
        k_idx, i_idx = complete_pairs(y, k_idx, i_idx, xyz, R, t, complete_tol_mm)
        if len(k_idx) > n:
            R, t = absolute_orientation(xyz[i_idx], y[k_idx], w[k_idx])
    x = xyz[i_idx]
    centres = x @ R.T + t
    r_disc = radii[i_idx]
    rho_m = candidates.range_mm[k_idx].astype(float)
    sr = candidates.sigma_range_mm[k_idx].astype(float)
    if fit.mixed_pixel_radius_px > 0:
        cos_inc = np.abs(centres @ R[:, 2]) / np.linalg.norm(centres, axis=1)
        for a, k in enumerate(k_idx):
            d, sensitivity = unmixed_range(
                rho_m[a],
                candidates.mixing[k],
                r_disc[a] * camera.fx / rho_m[a],
                cos_inc[a],
                fit.mixed_pixel_radius_px,
            )
            rho_m[a] = d
            sr[a] = np.hypot(sr[a], sensitivity)
    uv_obs = candidates.uv_px[k_idx].astype(float)
    if fit.correct_perspective_bias:
        uv_obs = uv_obs - disc_centre_offsets(camera.K, centres, R[:, 2], r_disc)
    e_obs = bearings(uv_obs, camera.K, camera.dist)
    sb = candidates.sigma_px[k_idx] / camera.fx
    observed = Reflectors(x=x, e=e_obs, rho=rho_m, sr=sr, sb=sb)
    cap = fit.max_systematic_centroid_sigma_px / camera.fx
    result = fit_with_outliers(observed, fit, cap, offset_prior)
    return SolvedPairs(k_idx=k_idx, i_idx=i_idx, uv=uv_obs, observed=observed, result=result)
