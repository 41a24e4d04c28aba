"""§5 from matched pairs in one compiled call, for both modes: weighted SVD (Eqs.
40-50), completion with unmatched blobs, SVD again, the perspective-bias correction of
the centroids, back-projection (Eq. 8) and the fit with its outlier step
(``pose.fit_with_outliers``). ``solve.PoseSolver.solve`` (acquisition) and
``tracking_frame.track_frame`` (tracking, where every blob is matched and completion
adds nothing) call it; the verification against the frame stays in ``PoseSolver``."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.core.kernels.camera import bearings
from tofpose.stages.extraction.kernels.mixed_pixels import unmixed_range
from tofpose.stages.extraction.kernels.perspective import disc_centre_offsets
from tofpose.stages.pose.kernels.pose import absolute_orientation, fit_with_outliers
from tofpose.stages.pose.records import Reflectors, SolvedPairs


@jit
def complete_pairs(y, k_idx, i_idx, xyz, R, t, tol_mm):
    """Add unmatched blobs that sit on a predicted unmatched reflector: repeatedly the
    closest (blob, reflector) pair under ``tol_mm`` (the first in row-major order among
    equals), each blob and reflector used once. y (g, 3) observed, xyz (e, 3) catalog;
    k_idx, i_idx (m,) the matched pairs. Returns the extended k_idx, i_idx."""
    g, e = y.shape[0], xyz.shape[0]
    used_k = np.zeros(g, np.bool_)
    used_i = np.zeros(e, np.bool_)
    for a in range(k_idx.shape[0]):
        used_k[k_idx[a]] = True
        used_i[i_idx[a]] = True
    free_k = np.flatnonzero(~used_k)
    free_i = np.flatnonzero(~used_i)
    nk, ni = free_k.shape[0], free_i.shape[0]
    out_k = np.empty(k_idx.shape[0] + min(nk, ni), np.int64)
    out_i = np.empty(out_k.shape[0], np.int64)
    out_k[: k_idx.shape[0]] = k_idx
    out_i[: i_idx.shape[0]] = i_idx
    n = k_idx.shape[0]
    if nk == 0 or ni == 0:
        return out_k[:n], out_i[:n]
    dist = np.empty((nk, ni))
    for b in range(ni):
        p = xyz[free_i[b]]
        px = R[0, 0] * p[0] + R[0, 1] * p[1] + R[0, 2] * p[2] + t[0]
        py = R[1, 0] * p[0] + R[1, 1] * p[1] + R[1, 2] * p[2] + t[1]
        pz = R[2, 0] * p[0] + R[2, 1] * p[1] + R[2, 2] * p[2] + t[2]
        for a in range(nk):
            q = y[free_k[a]]
            dist[a, b] = np.sqrt((q[0] - px) ** 2 + (q[1] - py) ** 2 + (q[2] - pz) ** 2)
    while True:
        best, ba, bb = np.inf, -1, -1
        for a in range(nk):
            for b in range(ni):
                if dist[a, b] < best:
                    best, ba, bb = dist[a, b], a, b
        if not best < tol_mm:
            break
        out_k[n], out_i[n] = free_k[ba], free_i[bb]
        n += 1
        dist[ba, :] = np.inf
        dist[:, bb] = np.inf
    return out_k[:n], out_i[:n]


@jit
def solve_pairs(candidates, k_idx, i_idx, catalog, camera, fit, complete_tol_mm, offset_prior):
    """The pose of matched pairs (module docstring).

    candidates : the frame's candidate reflectors (a ``core.records.Candidates``: their
    centroids, ranges, points (Eq. 8), weights (Eq. 21), sigmas and mixing sums (NaN
    rows: none)); k_idx, i_idx (m,) : matched (candidate, catalog) pairs; catalog :
    ``records.CatalogRecord``; camera : ``records.CameraRecord``; fit : the
    ``records.FitSettings`` (``fit_with_outliers``'; its bearing cap given in px, taken to
    rad with fx; with ``correct_perspective_bias`` the centroids less the perspective
    bias; matched discs whose apparent radius is below ``mixed_pixel_radius_px`` take the
    mixing model's range instead of the median, ``mixed_pixels.unmixed_range``, with the
    disc's area and incidence from the SVD pose; <= 0: never); complete_tol_mm :
    completion's tolerance (<= 0: none); offset_prior : a ``records.RangeOffsetPrior``.

    Returns the ``pose.records.SolvedPairs``: k_idx, i_idx (m',) after completion, the
    corrected centroids (m', 2), the matched reflectors as observed (bearings of the
    corrected centroids, ranges and range sigmas with the mixing model's own uncertainty
    added where it replaced the median, the noise model's bearing sigmas) and what
    ``fit_with_outliers`` returns. The observed ranges are as measured: the offset is not
    taken out of them here.
    """
    xyz, radii = catalog.xyz, catalog.radii_mm
    K, fx, fy, cx, cy, dist = camera.K, camera.fx, camera.fy, camera.cx, camera.cy, camera.dist
    y, w = candidates.y_mm, candidates.weights
    x = np.empty((k_idx.shape[0], 3))
    for a in range(k_idx.shape[0]):
        x[a] = xyz[i_idx[a]]
    R, t = absolute_orientation(x, y[k_idx], w[k_idx])
    if complete_tol_mm > 0:
        k_idx, i_idx = complete_pairs(y, k_idx, i_idx, xyz, R, t, complete_tol_mm)
        if k_idx.shape[0] > x.shape[0]:  # pairs added: fit them all
            x = np.empty((k_idx.shape[0], 3))
            for a in range(k_idx.shape[0]):
                x[a] = xyz[i_idx[a]]
            R, t = absolute_orientation(x, y[k_idx], w[k_idx])
    m = k_idx.shape[0]
    uv_obs = np.empty((m, 2))
    r_disc = np.empty(m)
    rho_m = np.empty(m)
    sr = np.empty(m)
    centres = np.empty((m, 3))  # x R^T + t, the discs' centres in the camera frame
    for a in range(m):
        uv_obs[a] = candidates.uv_px[k_idx[a]]
        r_disc[a] = radii[i_idx[a]]
        rho_m[a] = candidates.range_mm[k_idx[a]]
        sr[a] = candidates.sigma_range_mm[k_idx[a]]
        for b in range(3):
            centres[a, b] = R[b, 0] * x[a, 0] + R[b, 1] * x[a, 1] + R[b, 2] * x[a, 2] + t[b]
    if fit.mixed_pixel_radius_px > 0:
        for a in range(m):
            c = centres[a]
            norm_c = np.sqrt(c[0] ** 2 + c[1] ** 2 + c[2] ** 2)
            cos_inc = abs(R[0, 2] * c[0] + R[1, 2] * c[1] + R[2, 2] * c[2]) / norm_c
            d, sens = unmixed_range(
                rho_m[a],
                candidates.mixing[k_idx[a]],
                r_disc[a] * fx / rho_m[a],
                cos_inc,
                fit.mixed_pixel_radius_px,
            )
            rho_m[a] = d
            sr[a] = np.sqrt(sr[a] ** 2 + sens**2)
    if fit.correct_perspective_bias:
        uv_obs -= disc_centre_offsets(K, centres, R[:, 2].copy(), r_disc)
    e_obs = bearings(uv_obs, fx, fy, cx, cy, dist)
    sb = np.empty(m)
    for a in range(m):
        sb[a] = candidates.sigma_px[k_idx[a]] / fx
    observed = Reflectors(x=x, e=e_obs, rho=rho_m, sr=sr, sb=sb)
    result = fit_with_outliers(
        observed, fit, fit.max_systematic_centroid_sigma_px / fx, offset_prior
    )
    return SolvedPairs(k_idx=k_idx, i_idx=i_idx, uv=uv_obs, observed=observed, result=result)
