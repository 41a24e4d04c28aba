"""§4 as stated: correspondence by deterministic annealing (Eqs. 25-39), the one-to-one
assignment that reads its result, and the rigid residual check that ends it.

Shapes: observed (g, 3) mm, camera frame; catalog (e, 3) mm, target frame; A (g, e + 1)
assignment probabilities, column 0 the null label ("no reflector").
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment
from scipy.spatial.distance import cdist
from scipy.special import softmax

from tofpose.stages.matching.constants import FORBIDDEN
from tofpose.stages.pose.reference.pose import absolute_orientation


def pair_distances(points) -> np.ndarray:
    """Eqs. 25-26: the distances D_ij between catalog reflectors, or d_kl between
    observed ones, (n, n)."""
    p = np.asarray(points, float)
    return cdist(p, p)


def pair_potentials(observed, catalog, alpha_mm: float, clip: float) -> np.ndarray:
    """Eq. 36's pair term min(rho_kilj^2, (clip alpha)^2) - alpha^2 with rho_kilj =
    |d_kl - D_ij|; 0 where l == k or j == i (no self-support). (g, e, g, e)."""
    d, D = pair_distances(observed), pair_distances(catalog)
    rho = np.abs(d[:, None, :, None] - D[None, :, None, :])
    P = np.minimum(rho**2, (clip * alpha_mm) ** 2) - alpha_mm**2
    g, e = d.shape[0], D.shape[0]
    P[np.arange(g), :, np.arange(g), :] = 0.0
    P[:, np.arange(e), :, np.arange(e)] = 0.0
    return P


def size_mismatch(observed_diameter_mm, catalog_diameter_mm) -> np.ndarray:
    """Ours: the unary size term (ln(d_obs / D_i) / ln 1.6)^2, capped at 4, 0 where a
    diameter is unknown (NaN). (g,), (e,) -> (g, e)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.log(
            np.asarray(observed_diameter_mm, float)[:, None]
            / np.asarray(catalog_diameter_mm, float)[None, :]
        )
        v = (ratio / np.log(1.6)) ** 2
    return np.where(np.isnan(v), 0.0, np.minimum(v, 4.0))


def anneal(P, unary, psi_start: float, psi_end: float, growth: float):
    """Eqs. 35-39: from the uniform A (Eq. 39), while psi <= psi_end: the energy of each
    label E_ki = sum_lj P_kilj A_lj + unary_ki (Eq. 36), A_k. = softmax(-psi E_k.) over
    the labels with the null label's energy 0 (Eq. 37), psi <- growth psi (Eq. 35).
    P (g, e, g, e); unary (g, e); psi in 1 / mm^2. Returns A (g, e + 1), iterations."""
    g, e = unary.shape
    A = np.full((g, e + 1), 1.0 / (1 + e))
    Pm = np.asarray(P, float).reshape(g * e, g * e)
    psi, iterations = psi_start, 0
    while psi <= psi_end:
        E = (Pm @ A[:, 1:].reshape(-1)).reshape(g, e) + unary
        logits = np.column_stack((np.zeros(g), -psi * E))
        A = softmax(logits, axis=1)
        psi *= growth
        iterations += 1
    return A, iterations


def soft_assignment(
    observed,
    catalog,
    alpha_mm: float,
    clip: float,
    use_size: bool,
    observed_diameter_mm,
    catalog_diameter_mm,
    size_scale: float,
    psi_start: float,
    psi_end: float,
    growth: float,
):
    """Eqs. 35-39 from the points: ``anneal`` of the ``pair_potentials`` with the unary
    term ``size_scale * size_mismatch`` (``use_size``; else none: all zero).
    Returns A (g, e + 1), iterations."""
    P = pair_potentials(observed, catalog, alpha_mm, clip)
    g, e = P.shape[0], P.shape[1]
    unary = (
        size_scale * size_mismatch(observed_diameter_mm, catalog_diameter_mm)
        if use_size
        else np.zeros((g, e))
    )
    return anneal(P, unary, psi_start, psi_end, growth)


def one_to_one(A) -> tuple[np.ndarray, list[int]]:
    """The most probable one-to-one reading of A: the assignment (SciPy's) minimising
    sum -log A over catalog labels and one private null label per blob. Returns the pairs
    (m, 2) (blob k, catalog i) by blob, and the blobs left unmatched."""
    g, e = A.shape[0], A.shape[1] - 1
    nl = -np.log(np.maximum(A, 1e-300))
    cost = np.full((g, e + g), FORBIDDEN)
    cost[:, :e] = nl[:, 1:]
    cost[np.arange(g), e + np.arange(g)] = nl[:, 0]
    rows, cols = linear_sum_assignment(cost)
    real = (cols < e) & (cost[rows, cols] < FORBIDDEN)
    pairs = np.column_stack((rows[real], cols[real])).astype(np.int64)
    return pairs, sorted(set(range(g)) - set(rows[real].tolist()))


def rigid_residual_check(observed, catalog, pairs, weights, tol_mm, min_matches: int):
    """Drop the pair whose rigid-fit residual (Eqs. 40-50 on the kept pairs) over its
    blob's tolerance is largest, until every residual is within its tolerance. Returns
    (kept pairs (m', 2), rejected blobs in the order dropped, ok); not ok (and every pair
    rejected) when fewer than ``min_matches`` would remain. tol_mm (g,) per blob."""
    observed, catalog = np.asarray(observed, float), np.asarray(catalog, float)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    tol = np.asarray(tol_mm, float)
    alive = np.ones(len(pairs), bool)
    rejected: list[int] = []
    while alive.sum() >= min_matches:
        kp = pairs[alive]
        y, x, w = observed[kp[:, 0]], catalog[kp[:, 1]], np.asarray(weights, float)[kp[:, 0]]
        R, t = absolute_orientation(x, y, w)
        residual = np.linalg.norm(y - (x @ R.T + t), axis=1)
        worst = int(np.argmax(residual / tol[kp[:, 0]]))
        if residual[worst] <= tol[kp[worst, 0]]:
            return kp, rejected, True
        rejected.append(int(kp[worst, 0]))
        alive[np.flatnonzero(alive)[worst]] = False
    rejected += pairs[alive, 0].tolist()
    return np.empty((0, 2), np.int64), rejected, False
