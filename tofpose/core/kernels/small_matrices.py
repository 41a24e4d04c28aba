"""Linear algebra of §5's small matrices (3 x 3 rotations, 6 x 6 normal equations) as
plain compiled loops.

LAPACK and BLAS do these in microseconds when their code is in the cache, but in the
pipeline's stream a frame's other work evicts it between calls, and each call then costs
several times as much (a 3 x 3 SVD, the Gauss-Newton fit). These loops are short and
stay fast wherever they are called from. Arithmetic: Horn's closed form for the
rotation (the eigenvector of a 4 x 4 symmetric matrix, by Jacobi rotations) and Cholesky
for the symmetric positive-definite normal equations; both agree with the LAPACK
versions they replace to rounding (tests/tofpose/core/kernels/test_small_matrices.py).
"""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit


@jit
def symmetric_eigen(N):
    """Eigenvalues (n,) and eigenvectors (n, n) as columns of a symmetric N (n, n), by
    cyclic Jacobi rotations until the off-diagonal part is negligible."""
    n = N.shape[0]
    a = N.copy()
    v = np.eye(n)
    for _sweep in range(50):
        off = 0.0
        scale = 0.0
        for p in range(n):
            scale += a[p, p] * a[p, p]
            for q in range(p + 1, n):
                off += a[p, q] * a[p, q]
        if off <= 1e-32 * scale or off == 0.0:
            break
        for p in range(n - 1):
            for q in range(p + 1, n):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                theta = (a[q, q] - a[p, p]) / (2.0 * apq)
                tan = np.sign(theta) / (abs(theta) + np.sqrt(theta * theta + 1.0))
                if theta == 0.0:
                    tan = 1.0
                c = 1.0 / np.sqrt(tan * tan + 1.0)
                s = tan * c
                for k in range(n):  # columns p, q of a
                    akp, akq = a[k, p], a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(n):  # rows p, q of a
                    apk, aqk = a[p, k], a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                for k in range(n):
                    vkp, vkq = v[k, p], v[k, q]
                    v[k, p] = c * vkp - s * vkq
                    v[k, q] = s * vkp + c * vkq
    values = np.empty(n)
    for p in range(n):
        values[p] = a[p, p]
    return values, v


@jit
def _symmetric_eigen_4(N):
    """``symmetric_eigen`` of a 4 x 4 N (Horn's quaternion matrix)."""
    return symmetric_eigen(N)


@jit
def lower_solve(L, B):
    """L^-1 B (n, k) for a lower-triangular L (n, n) and B (n, k), by forward
    substitution column by column."""
    n, k = B.shape
    out = np.empty((n, k))
    for c in range(k):
        for i in range(n):
            s = B[i, c]
            for j in range(i):
                s -= L[i, j] * out[j, c]
            out[i, c] = s / L[i, i]
    return out


@jit
def rotation_from_correlation(S):
    """The rotation R (3, 3) of the weighted absolute orientation (Eqs. 45-49): the one
    maximising sum_i w_i (y_i - y_bar) . R (x_i - x_bar) = trace(R S), S (3, 3) =
    sum_i w_i (x_i - x_bar)(y_i - y_bar)^T. Horn's (1987) closed form: the unit
    quaternion that is the eigenvector of the largest eigenvalue of a symmetric 4 x 4
    matrix built from S. It equals Eq. 49's V diag(1, 1, det(V U^T)) U^T of the SVD
    S = U D V^T (a proper rotation, also for the nearly planar pattern)."""
    sxx, sxy, sxz = S[0, 0], S[0, 1], S[0, 2]
    syx, syy, syz = S[1, 0], S[1, 1], S[1, 2]
    szx, szy, szz = S[2, 0], S[2, 1], S[2, 2]
    N = np.empty((4, 4))
    N[0, 0] = sxx + syy + szz
    N[0, 1] = N[1, 0] = syz - szy
    N[0, 2] = N[2, 0] = szx - sxz
    N[0, 3] = N[3, 0] = sxy - syx
    N[1, 1] = sxx - syy - szz
    N[1, 2] = N[2, 1] = sxy + syx
    N[1, 3] = N[3, 1] = szx + sxz
    N[2, 2] = -sxx + syy - szz
    N[2, 3] = N[3, 2] = syz + szy
    N[3, 3] = -sxx - syy + szz
    values, vectors = _symmetric_eigen_4(N)
    best = 0
    for p in range(1, 4):
        if values[p] > values[best]:
            best = p
    w, x, y, z = vectors[0, best], vectors[1, best], vectors[2, best], vectors[3, best]
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    R = np.empty((3, 3))
    R[0, 0] = w * w + x * x - y * y - z * z
    R[0, 1] = 2.0 * (x * y - w * z)
    R[0, 2] = 2.0 * (x * z + w * y)
    R[1, 0] = 2.0 * (x * y + w * z)
    R[1, 1] = w * w - x * x + y * y - z * z
    R[1, 2] = 2.0 * (y * z - w * x)
    R[2, 0] = 2.0 * (x * z - w * y)
    R[2, 1] = 2.0 * (y * z + w * x)
    R[2, 2] = w * w - x * x - y * y + z * z
    return R


@jit
def gram(J):
    """J^T J (n, n) of J (m, n)."""
    m, n = J.shape
    H = np.zeros((n, n))
    for a in range(n):
        for b in range(a, n):
            s = 0.0
            for i in range(m):
                s += J[i, a] * J[i, b]
            H[a, b] = s
            H[b, a] = s
    return H


@jit
def transposed_times(J, r):
    """J^T r (n,) of J (m, n) and r (m,)."""
    m, n = J.shape
    out = np.zeros(n)
    for a in range(n):
        s = 0.0
        for i in range(m):
            s += J[i, a] * r[i]
        out[a] = s
    return out


@jit
def cholesky(H):
    """Lower-triangular L (n, n) with L L^T = H for a symmetric positive-definite H, and
    whether it is: False when a pivot is not positive (H singular to working precision,
    e.g. a Jacobian of too few points), and L is then meaningless."""
    n = H.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = H[j, j]
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0.0:  # also NaN
            return L, False
        L[j, j] = np.sqrt(s)
        for i in range(j + 1, n):
            s = H[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return L, True


@jit
def cholesky_solve(L, b):
    """x (n,) with L L^T x = b (n,), L from ``cholesky``."""
    n = L.shape[0]
    y = np.empty(n)
    for i in range(n):
        s = b[i]
        for k in range(i):
            s -= L[i, k] * y[k]
        y[i] = s / L[i, i]
    x = np.empty(n)
    for i in range(n - 1, -1, -1):
        s = y[i]
        for k in range(i + 1, n):
            s -= L[k, i] * x[k]
        x[i] = s / L[i, i]
    return x


@jit
def cholesky_inverse(L):
    """(L L^T)^-1 (n, n), L from ``cholesky``."""
    n = L.shape[0]
    out = np.empty((n, n))
    e = np.zeros(n)
    for j in range(n):
        e[:] = 0.0
        e[j] = 1.0
        col = cholesky_solve(L, e)
        for i in range(n):
            out[i, j] = col[i]
    for i in range(n):  # exactly symmetric
        for j in range(i + 1, n):
            s = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = s
            out[j, i] = s
    return out


@jit
def matmul3(A, B):
    """A B of two (3, 3) matrices."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            out[i, j] = A[i, 0] * B[0, j] + A[i, 1] * B[1, j] + A[i, 2] * B[2, j]
    return out
