"""The deterministic-annealing iteration of §4 (Eqs. 35-39) and its pair potentials
(Eq. 36), compiled; the reference and its documentation are
``tofpose.stages.matching.matching.anneal``
and ``tofpose.stages.matching.matching.pair_compatibility``."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit
from tofpose.stages.matching.constants import FORBIDDEN


@jit
def anneal_assignment(Pm, unary, psi, psi_end, growth):
    """Iterate Eqs. 36-37 from the uniform A (Eq. 39) while psi <= psi_end, psi growing
    by ``growth`` (Eq. 35).

    Pm : (g e, g e) pair potentials rho^2 - alpha^2 (Eq. 36) over (k, i) x (l, j);
    unary : (g, e) per-blob costs added to the energy (all zero for none); psi, psi_end
    in 1 / mm^2. Returns A (g, e + 1), column 0 the null label, and the iterations.
    """
    g, e = unary.shape
    A = np.full((g, e + 1), 1.0 / (1 + e))
    a = np.empty(g * e)
    it = 0
    while psi <= psi_end:
        for k in range(g):
            for i in range(e):
                a[k * e + i] = A[k, i + 1]
        E = Pm @ a
        for k in range(g):
            top = 0.0  # the null label's logit (F_k0 = 1)
            for i in range(e):
                top = max(top, -psi * (E[k * e + i] + unary[k, i]))
            s = np.exp(0.0 - top)
            A[k, 0] = s
            for i in range(e):
                f = np.exp(-psi * (E[k * e + i] + unary[k, i]) - top)
                A[k, i + 1] = f
                s += f
            for i in range(e + 1):
                A[k, i] /= s
        psi *= growth
        it += 1
    return A, it


@jit
def _pairwise_distances(points):
    """(n, n) Euclidean distances of points (n, 3), summed as NumPy's norm does."""
    n = points.shape[0]
    out = np.empty((n, n))
    for a in range(n):
        for b in range(n):
            dx = points[a, 0] - points[b, 0]
            dy = points[a, 1] - points[b, 1]
            dz = points[a, 2] - points[b, 2]
            out[a, b] = np.sqrt(dx * dx + dy * dy + dz * dz)
    return out


@jit
def pair_potentials(observed, catalog, alpha, clip):
    """Pair potential min(rho_kilj^2, (clip alpha)^2) - alpha^2 (Eq. 36, rho = |d_kl -
    D_ij|, Eqs. 25-26), shape (gamma, eta, gamma, eta), 0 where l == k or j == i.

    observed : (gamma, 3) mm, camera frame; catalog : (eta, 3) mm, target frame.
    """
    g, e = observed.shape[0], catalog.shape[0]
    o = _pairwise_distances(observed)
    c = _pairwise_distances(catalog)
    cap = (clip * alpha) ** 2
    a2 = alpha**2
    P = np.zeros((g, e, g, e))
    for k in range(g):
        for i in range(e):
            for m in range(g):
                if m == k:
                    continue
                for j in range(e):
                    if j != i:
                        r = abs(o[k, m] - c[i, j])
                        P[k, i, m, j] = min(r * r, cap) - a2
    return P


@jit
def size_mismatch(observed_diameter, catalog_diameter):
    """Unary size term (``matching.size_unary``): (ln(d_obs / D_i) / ln 1.6)^2 capped at
    4, and 0 where it is undefined (a NaN diameter); (gamma,), (eta,) -> (gamma, eta)."""
    g, e = observed_diameter.shape[0], catalog_diameter.shape[0]
    out = np.empty((g, e))
    ln16 = np.log(1.6)
    for k in range(g):
        for i in range(e):
            v = (np.log(observed_diameter[k] / catalog_diameter[i]) / ln16) ** 2
            if v != v:  # NaN: unknown
                v = 0.0
            elif v > 4.0:  # also +inf, a zero or infinite diameter
                v = 4.0
            out[k, i] = v
    return out


@jit
def soft_assignment(
    observed,
    catalog,
    alpha,
    clip,
    use_size,
    observed_diameter,
    catalog_diameter,
    size_scale,
    psi,
    psi_end,
    growth,
):
    """§4's soft assignment in one call (the first steps of ``matching.match_reflectors``):
    ``pair_potentials`` of observed (g, 3) and catalog (e, 3) mm with tolerance
    ``alpha`` mm and clip factor ``clip``; the unary size term ``size_scale *
    size_mismatch(observed_diameter (g,), catalog_diameter (e,))`` when ``use_size``
    (``size_scale`` = the size weight times alpha^2), else all zero; then
    ``anneal_assignment`` from ``psi`` to ``psi_end`` (1 / mm^2) by ``growth``.
    Returns A (g, e + 1), column 0 the null label, and the iterations."""
    g, e = observed.shape[0], catalog.shape[0]
    P = pair_potentials(observed, catalog, alpha, clip)
    if use_size:
        unary = size_scale * size_mismatch(observed_diameter, catalog_diameter)
    else:
        unary = np.zeros((g, e))
    return anneal_assignment(P.reshape(g * e, g * e), unary, psi, psi_end, growth)


@jit
def assignment_costs(neg_log_a):
    """The cost matrix (g, e + g) of ``matching.one_to_one`` from -log A (g, e + 1):
    catalog columns first, then one private null column per blob (its own null cost on
    the diagonal, ``FORBIDDEN`` elsewhere)."""
    g, e1 = neg_log_a.shape
    e = e1 - 1
    cost = np.full((g, e + g), FORBIDDEN)
    for k in range(g):
        for i in range(e):
            cost[k, i] = neg_log_a[k, i + 1]
        cost[k, e + k] = neg_log_a[k, 0]
    return cost


@jit
def assigned_pairs(rows, cols, cost, e):
    """The (k, i) pairs (m, 2) int64 of an assignment (rows, cols) of ``assignment_costs``
    that are real catalog labels at an allowed cost, and the blobs left unmatched (u,)
    int64, ascending."""
    g = cost.shape[0]
    matched = np.zeros(g, np.bool_)
    pairs = np.empty((rows.shape[0], 2), np.int64)
    m = 0
    for a in range(rows.shape[0]):
        if cols[a] < e and cost[rows[a], cols[a]] < FORBIDDEN:
            pairs[m, 0], pairs[m, 1] = rows[a], cols[a]
            matched[rows[a]] = True
            m += 1
    return pairs[:m], np.flatnonzero(~matched)
