"""Reflector correspondence by deterministic annealing (§4, Eqs. 25-39).

Observed reflectors y_k (k = 1..gamma) are assigned to catalog reflectors x_i
(i = 1..eta) or to the null label 0 (spurious blob). The assignment matrix A
(gamma x (eta + 1)) starts uniform (Eq. 39) and is iterated as

    F_ki = exp(-psi * sum_{l != k} sum_{j != i, j > 0} A_lj (rho_kilj^2 - alpha^2))  i > 0
    F_k0 = 1                                                                           (Eq. 36)
    A_ki = F_ki / sum_h F_kh                                                          (Eq. 37)

with psi growing geometrically (Eq. 35). rho_kilj = | ||y_k - y_l|| - ||x_i - x_j|| |
(Eqs. 25-26). Our additions, each documented in docs/algorithm.md:

* rho^2 is clipped at ``clip_factor^2 * alpha^2`` so that one grossly wrong pair cannot
  outweigh all the support of the right ones (robust pair potential);
* an optional unary term compares a blob's apparent diameter (px * rho / f) with the
  catalog diameters (35 vs 80 mm markers), breaking symmetric distance ties;
* the final labels are one-to-one (Hungarian algorithm on -log A with one null column per
  blob); the paper only normalises rows;
* a rigid residual check rejects the worst pair until all residuals are within tolerance,
  refusing the match when fewer than ``min_matches`` remain.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tofpose.config import MatchingConfig
from tofpose.stages.matching.arithmetic import COMPILED, MatchingArithmetic
from tofpose.stages.matching.records import TripletBest, TripletProblem, TripletRule


@dataclass
class MatchResult:
    """Outcome of matching.

    pairs : ndarray (m, 2) int, rows (observed index k, catalog index i).
    unmatched : list of observed indices assigned to the null label.
    A : ndarray (gamma, eta + 1), the final assignment probabilities.
    iterations : annealing iterations (RANSAC: observed triplets tried).
    alpha_mm : tolerance used.
    reason : empty when ok, else why no consistent match was found.
    """

    pairs: np.ndarray
    unmatched: list[int]
    A: np.ndarray
    iterations: int
    alpha_mm: float
    reason: str = ""

    @property
    def ok(self) -> bool:
        return not self.reason


def pair_compatibility(
    observed_mm: np.ndarray,
    catalog_mm: np.ndarray,
    alpha_mm: float,
    clip_factor: float,
    *,
    arithmetic: MatchingArithmetic = COMPILED,
) -> np.ndarray:
    """Pair potential rho_kilj^2 - alpha^2 (Eq. 36), shape (gamma, eta, gamma, eta).

    rho_kilj = |d_kl - D_ij| compares the distance between observed blobs k and l (Eq. 26)
    with that between catalog reflectors i and j (Eq. 25); rho^2 is clipped at
    (clip_factor alpha)^2. Entries with l == k or j == i are zero (no self-support).
    Computed by ``kernels.annealing.pair_potentials`` (``arithmetic``'s).
    """
    return arithmetic.pair_potentials(
        np.ascontiguousarray(observed_mm, float),
        np.ascontiguousarray(catalog_mm, float),
        float(alpha_mm),
        float(clip_factor),
    )


def size_unary(
    observed_diameter_mm: np.ndarray | None,
    catalog_diameter_mm: np.ndarray,
    *,
    arithmetic: MatchingArithmetic = COMPILED,
) -> np.ndarray | None:
    """Unary mismatch (gamma, eta) of apparent vs catalog diameter, 0 where unknown.

    ``(ln(d_obs / D_i) / ln 1.6)^2`` capped at 4: a 35 mm blob seen as 80 mm costs ~3.
    """
    if observed_diameter_mm is None:
        return None
    return arithmetic.size_mismatch(
        np.ascontiguousarray(observed_diameter_mm, float).reshape(-1),
        np.ascontiguousarray(catalog_diameter_mm, float).reshape(-1),
    )


def anneal(
    P: np.ndarray,
    unary: np.ndarray | None,
    alpha_mm: float,
    config: MatchingConfig,
    *,
    arithmetic: MatchingArithmetic = COMPILED,
) -> tuple[np.ndarray, int]:
    """Run Eqs. 35-39; returns A of shape (gamma, eta + 1) and the iteration count."""
    g, e = P.shape[0], P.shape[1]
    u = np.zeros((g, e)) if unary is None else config.size_weight * alpha_mm**2 * unary
    return arithmetic.anneal_assignment(
        np.ascontiguousarray(P.reshape(g * e, g * e)),
        np.ascontiguousarray(u, float),
        config.psi_start / alpha_mm**2,
        config.psi_end / alpha_mm**2,
        config.growth,
    )


def one_to_one(
    A: np.ndarray, *, arithmetic: MatchingArithmetic = COMPILED
) -> tuple[np.ndarray, list[int]]:
    """Hungarian assignment on -log A with a private null column per observed blob.

    A : (g, e + 1) assignment probabilities, column 0 the null label. Returns the pairs
    (m, 2) (blob k, catalog i) and the unmatched blobs. Compiled: the cost matrix and the
    reading of the assignment are kernels (``kernels.annealing.assignment_costs``,
    ``assigned_pairs``), the assignment is SciPy's (``arithmetic.COMPILED.one_to_one``)."""
    return arithmetic.one_to_one(A)


def match_reflectors(
    observed_mm: np.ndarray,
    catalog_mm: np.ndarray,
    config: MatchingConfig | None = None,
    *,
    observed_diameter_mm: np.ndarray | None = None,
    catalog_diameter_mm: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    arithmetic: MatchingArithmetic = COMPILED,
) -> MatchResult:
    """Match observed 3-D reflector positions (gamma, 3) to a catalog (eta, 3).

    Parameters
    ----------
    observed_mm : ndarray (gamma, 3), camera frame.
    catalog_mm : ndarray (eta, 3), target frame.
    observed_diameter_mm : optional (gamma,), apparent diameters for the size term.
    catalog_diameter_mm : optional (eta,).
    weights : optional (gamma,), used by the rigid residual check's SVD.
    arithmetic : the implementation of the arithmetic (``tofpose.arithmetic``).
    """
    cfg = config or MatchingConfig()
    g, e = len(observed_mm), len(catalog_mm)
    alpha = cfg.alpha_for(observed_mm)
    empty = np.empty((0, 2), int)
    if g < cfg.min_matches:
        return MatchResult(
            empty,
            list(range(g)),
            np.zeros((g, e + 1)),
            0,
            alpha,
            f"only {g} candidate reflector(s), need {cfg.min_matches}",
        )
    # pair_compatibility, size_unary and anneal in one call (kernels.annealing)
    use_size = (
        cfg.size_weight > 0 and catalog_diameter_mm is not None and observed_diameter_mm is not None
    )
    no_size = np.empty(0)
    A, iters = arithmetic.soft_assignment(
        np.ascontiguousarray(observed_mm, float),
        np.ascontiguousarray(catalog_mm, float),
        float(alpha),
        float(cfg.clip_factor),
        use_size,
        np.ascontiguousarray(observed_diameter_mm, float).reshape(-1) if use_size else no_size,
        np.ascontiguousarray(catalog_diameter_mm, float).reshape(-1) if use_size else no_size,
        cfg.size_weight * alpha**2 if use_size else 0.0,
        cfg.psi_start / alpha**2,
        cfg.psi_end / alpha**2,
        cfg.growth,
    )
    pairs, unmatched = one_to_one(A, arithmetic=arithmetic)
    w = np.ones(g) if weights is None else np.asarray(weights, float)
    # Without weights every pair gets sigma = alpha, i.e. the tolerance residual_factor alpha.
    tol = cfg.pair_tolerance_mm(alpha, w if weights is not None else np.full(g, alpha**-2.0))
    pairs, rejected, reason = rigid_residual_check(
        observed_mm, catalog_mm, pairs, w, tol, cfg.min_matches, arithmetic=arithmetic
    )
    unmatched = sorted(set(unmatched) | set(rejected))
    return MatchResult(pairs, unmatched, A, iters, alpha, reason)


def rigid_residual_check(
    observed_mm: np.ndarray,
    catalog_mm: np.ndarray,
    pairs: np.ndarray,
    weights: np.ndarray,
    tol_mm: float | np.ndarray,
    min_matches: int,
    *,
    arithmetic: MatchingArithmetic = COMPILED,
) -> tuple[np.ndarray, list[int], str]:
    """Drop the worst pair until every rigid-fit residual is within its tolerance.

    ``tol_mm`` is a scalar or one tolerance per observed reflector (gamma,). Each round
    fits the kept pairs (weighted SVD, Eqs. 40-50) and drops the pair with the largest
    residual / tolerance (``kernels.residual_check.prune_pairs``).

    Returns (pairs kept (m, 2), observed indices rejected, reason or "").
    """
    observed_mm = np.ascontiguousarray(observed_mm, dtype=float)
    tol_all = np.asarray(tol_mm, float)
    if tol_all.ndim == 0:
        tol_all = np.full(len(observed_mm), float(tol_all))
    kept, rejected, ok = arithmetic.prune_pairs(
        observed_mm,
        np.ascontiguousarray(catalog_mm, dtype=float),
        np.ascontiguousarray(pairs, dtype=np.int64).reshape(-1, 2),
        np.ascontiguousarray(weights, dtype=float),
        np.ascontiguousarray(tol_all),
        min_matches,
    )
    if ok:
        return kept, rejected.tolist(), ""
    return (
        kept,
        rejected.tolist(),
        f"no rigidly consistent match of >= {min_matches} reflectors "
        f"(residual tolerance up to {np.max(tol_mm):.1f} mm)",
    )


def match_by_triplets(
    observed_mm: np.ndarray,
    catalog_mm: np.ndarray,
    alpha_mm: float,
    tol_mm: np.ndarray,
    facing: tuple[np.ndarray, float] | None = None,
    *,
    weights: np.ndarray | None = None,
    max_observed: int = 7,
    min_matches: int = 3,
    observed_triplets: np.ndarray | None = None,
    deadline_s: float | None = None,
    confidence: float | None = None,
    stats: dict | None = None,
    arithmetic: MatchingArithmetic = COMPILED,
) -> np.ndarray:
    """Exhaustive triplet hypotheses (ours): the fallback when annealing's answer fails
    verification (e.g. a mirror-image assignment of 3-4 markers at long range).

    For every observed triplet (among the first ``max_observed``) and every ordered catalog
    triplet whose three side lengths agree within ``alpha_mm``, fit the rigid pose, skip it
    unless it faces the camera (``facing`` = (the catalog's centroid (3,), the least
    cosine of the view angle), ``kernels.triplets.facing_cosine``; None: no constraint),
    and count observed points within their tolerance of a predicted reflector
    (one-to-one). Returns the pairs (m, 2) of the hypothesis with most inliers (ties:
    smaller weighted residual), or an empty array. The loop is compiled
    (``kernels.triplets.triplet_search``).

    observed_triplets : optional (T, 3) observed index triplets to try instead, in order
        (e.g. ``random_triplets`` for a RANSAC-style search over all blobs);
    deadline_s : optional ``time.perf_counter()`` value after which the search stops
        (looked at before every ``DEADLINE_CHUNK`` triplets);
    confidence : optional RANSAC stopping rule: stop once the probability that every
        observed triplet tried so far held an outlier is below ``1 - confidence``, for an
        inlier fraction estimated from the best hypothesis (``ransac_trials_needed``).
    stats : optional dict that receives ``triplets`` (observed triplets tried).
    arithmetic : the implementation of the arithmetic (``tofpose.arithmetic``).
    """
    import time
    from itertools import combinations

    observed = np.ascontiguousarray(observed_mm, dtype=float).reshape(-1, 3)
    catalog = np.ascontiguousarray(catalog_mm, dtype=float)
    n = len(observed)
    w = np.ones(n) if weights is None else np.ascontiguousarray(weights, dtype=float)
    tol = np.ascontiguousarray(np.broadcast_to(tol_mm, (n,)), dtype=float)
    if observed_triplets is None:
        g = min(n, max_observed)
        observed_triplets = np.array(list(combinations(range(g), 3)), np.int64)
    triplets = np.ascontiguousarray(observed_triplets, dtype=np.int64).reshape(-1, 3)
    cat_tri, cat_sides = arithmetic.catalog_triplets(catalog)
    centroid, cos_min = (np.zeros(3), -np.inf) if facing is None else facing
    problem = TripletProblem(
        observed=observed,
        catalog=catalog,
        weights=w,
        tol_mm=tol,
        alpha_mm=float(alpha_mm),
        cat_tri=cat_tri,
        cat_sides=cat_sides,
    )
    rule = TripletRule(
        constrain=facing is not None,
        centroid=np.ascontiguousarray(centroid, dtype=float),
        cos_min=float(cos_min),
        min_matches=int(min_matches),
        use_confidence=confidence is not None,
        confidence=0.0 if confidence is None else float(confidence),
    )
    best = TripletBest(pairs=np.empty((0, 2), np.int64), n_inliers=0, cost=np.inf, tried=0)
    step = max(len(triplets) if deadline_s is None else DEADLINE_CHUNK, 1)
    for s in range(0, len(triplets), step):
        if deadline_s is not None and time.perf_counter() > deadline_s:
            break
        best, done = arithmetic.triplet_search(problem, triplets[s : s + step], rule, best)
        if done:
            break
    if stats is not None:
        stats["triplets"] = best.tried
    return best.pairs


#: observed triplets tried between two looks at the clock (a few microseconds of work)
DEADLINE_CHUNK = 4

#: the standard RANSAC count (``kernels.triplets.trials_needed``)
ransac_trials_needed = COMPILED.trials_needed


def random_triplets(n_observed: int, rng: np.random.Generator) -> np.ndarray:
    """Every 3-subset of ``range(n_observed)`` once, in random order (RANSAC sampling
    without repetition), (T, 3) int64, for ``match_by_triplets(observed_triplets=...)``."""
    from itertools import combinations

    tris = np.array(list(combinations(range(n_observed), 3)), np.int64).reshape(-1, 3)
    return tris[rng.permutation(len(tris))]
