"""Medians with NumPy's arithmetic, for the kernels (``np.median`` averages the two middle
values of an even count in the array's own precision)."""

from __future__ import annotations

from tofpose.kernels import jit


@jit
def select_kth(v, k):
    """The k-th smallest value (0-based) of a 1-D array without NaNs, found in place
    (quickselect, median-of-three pivot, Hoare partition): afterwards nothing before
    index k is larger and nothing after it is smaller. numba's ``np.partition`` copies
    the array on every call; the kernels' medians run over blobs of up to a few thousand
    pixels several times a frame."""
    lo, hi = 0, v.shape[0] - 1
    while lo < hi:
        mid = (lo + hi) >> 1
        a, b, c = v[lo], v[mid], v[hi]
        if a > b:
            a, b = b, a
        if b > c:
            b = c
        pivot = max(a, b)
        i, j = lo, hi
        while i <= j:
            while v[i] < pivot:
                i += 1
            while pivot < v[j]:
                j -= 1
            if i <= j:
                v[i], v[j] = v[j], v[i]
                i += 1
                j -= 1
        if j < k:
            lo = i
        if k < i:
            hi = j
    return v[k]


@jit
def median_inplace(v):
    """``float(np.median(v))`` of a non-empty 1-D float32 or float64 array without NaNs;
    reorders ``v`` (pass a copy to keep it)."""
    n = v.shape[0]
    k = n >> 1
    upper = select_kth(v, k)
    if n & 1:
        return float(upper)
    lower = v[0]  # the largest of the k values now before index k
    for i in range(1, k):
        lower = max(lower, v[i])
    return float((lower + upper) / v.dtype.type(2.0))
