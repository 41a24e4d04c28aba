"""The linear sum assignment (SciPy's ``linear_sum_assignment``) as a kernel, for the
hypothesis loops that solve one small assignment per hypothesis (``kernels.triplets``):
compiled code cannot call SciPy's, and leaving the loop for it per hypothesis is what
made the NumPy loop slow.

The algorithm is SciPy's: the shortest augmenting path method for rectangular problems
of Crouse (2016, "On implementing 2D rectangular assignment algorithms", IEEE TAES 52(4),
pp. 1685-1686), with SciPy's choices where several answers are optimal (the remaining
columns scanned in reverse order, a free column preferred among equal path costs, a
matrix with more rows than columns solved transposed), so that it returns the pairs
SciPy returns; ``tests/tofpose/stages/matching/kernels/test_assignment.py`` compares the two on
thousands of matrices with ties."""

from __future__ import annotations

import numpy as np

from tofpose.core.compiled import jit


@jit
def _augmenting_path(cost, u, v, path, row4col, shortest, i, sr, sc):
    """The shortest augmenting path from row ``i`` (Crouse's Algorithm 2 in SciPy's
    form): its sink column (-1: infeasible) and its cost. ``cost`` (nr, nc) >= 0."""
    nc = cost.shape[1]
    min_val = 0.0
    remaining = np.empty(nc, np.int64)
    for it in range(nc):  # reverse order: a constant matrix gives the identity
        remaining[it] = nc - it - 1
    n_remaining = nc
    sr[:] = False
    sc[:] = False
    shortest[:] = np.inf
    sink = -1
    while sink == -1:
        index = -1
        lowest = np.inf
        sr[i] = True
        for it in range(n_remaining):
            j = remaining[it]
            r = min_val + cost[i, j] - u[i] - v[j]
            if r < shortest[j]:
                path[j] = i
                shortest[j] = r
            # among equal costs, a column that ends the path
            if shortest[j] < lowest or (shortest[j] == lowest and row4col[j] == -1):
                lowest = shortest[j]
                index = it
        min_val = lowest
        if min_val == np.inf:
            return -1, min_val
        j = remaining[index]
        if row4col[j] == -1:
            sink = j
        else:
            i = row4col[j]
        sc[j] = True
        n_remaining -= 1
        remaining[index] = remaining[n_remaining]
    return sink, min_val


@jit
def _col4row(cost):
    """Column of each row (nr <= nc) of the minimum-cost assignment; all -1 when the
    matrix is infeasible."""
    nr, nc = cost.shape
    c = cost - cost.min()
    u = np.zeros(nr)
    v = np.zeros(nc)
    shortest = np.empty(nc)
    path = np.full(nc, -1, np.int64)
    col4row = np.full(nr, -1, np.int64)
    row4col = np.full(nc, -1, np.int64)
    sr = np.zeros(nr, np.bool_)
    sc = np.zeros(nc, np.bool_)
    for cur in range(nr):
        sink, min_val = _augmenting_path(c, u, v, path, row4col, shortest, cur, sr, sc)
        if sink < 0:
            return np.full(nr, -1, np.int64)
        u[cur] += min_val  # the dual variables
        for i in range(nr):
            if sr[i] and i != cur:
                u[i] += min_val - shortest[col4row[i]]
        for j in range(nc):
            if sc[j]:
                v[j] -= min_val - shortest[j]
        j = sink  # augment the previous solution along the path
        while True:
            i = path[j]
            row4col[j] = i
            col4row[i], j = j, col4row[i]
            if i == cur:
                break
    return col4row


@jit
def linear_sum_assignment(cost):
    """``scipy.optimize.linear_sum_assignment(cost)`` for a finite (nr, nc) float64
    matrix: rows (k,) and cols (k,) int64 of the minimum-cost assignment, k = min(nr,
    nc), rows ascending. Empty arrays for an empty matrix."""
    nr, nc = cost.shape
    if nr == 0 or nc == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    if nr <= nc:
        return np.arange(nr), _col4row(cost)
    # more rows than columns: solve the transpose, then list the pairs by row
    row_of_col = _col4row(np.ascontiguousarray(cost.T))
    order = np.argsort(row_of_col)
    return row_of_col[order], order.astype(np.int64)
