"""The deterministic-annealing iteration of §4 (Eqs. 35-39), compiled; the reference
and its documentation are ``tofpose.matching.anneal``."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit


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
