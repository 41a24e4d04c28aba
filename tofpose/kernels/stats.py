"""Medians with NumPy's arithmetic, for the kernels (``np.median`` averages the two middle
values of an even count in the array's own precision)."""

from __future__ import annotations

import numpy as np

from tofpose.kernels import jit

#: segments of at most this many values are finished by insertion sort
_SMALL = 24


@jit
def select_pair(v, k):
    """The (k-1)-th and k-th smallest values (0-based; -inf for the first when k = 0) of
    a 1-D float array without NaNs. ``v`` is used as scratch: its contents afterwards
    are unspecified.

    Quickselect with an out-of-place, branch-free partition: every value is written to
    both ends of the other buffer and the ends advance by the comparisons' outcomes, so
    the loop has no data-dependent branch. On pixel values (a fresh blob each call) this
    is ~3x faster than an in-place Hoare partition, whose branches the processor
    mispredicts about half the time (12 -> 4 us for 1000 values); the values selected
    are the same, they are order statistics. numba's ``np.partition`` copies its input
    on every call as well."""
    n = v.shape[0]
    src, dst = v, np.empty(n, v.dtype)
    below = v.dtype.type(-np.inf)  # the largest value known to lie below the segment
    while n > _SMALL:
        a, b, c = src[0], src[n >> 1], src[n - 1]  # median-of-three pivot
        if a > b:
            a, b = b, a
        if b > c:
            b = c
        pivot = max(a, b)
        n_lt, n_gt = 0, 0
        for i in range(n):  # smaller values fill dst from the front, larger from the back
            x = src[i]
            dst[n_lt] = x
            dst[n - 1 - n_gt] = x
            n_lt += x < pivot
            n_gt += x > pivot
        if k < n_lt:
            src, dst, n = dst[:n_lt], src[:n_lt], n_lt
        elif k < n - n_gt:  # the k-th value equals the pivot
            if k > n_lt:
                return pivot, pivot
            for i in range(n_lt):
                below = max(below, dst[i])
            return below, pivot
        else:
            k -= n - n_gt
            src, dst, n = dst[n - n_gt : n], src[:n_gt], n_gt
            below = pivot
    for i in range(1, n):  # insertion sort of the last few
        x = src[i]
        j = i
        while j > 0 and src[j - 1] > x:
            src[j] = src[j - 1]
            j -= 1
        src[j] = x
    return (src[k - 1] if k > 0 else below), src[k]


@jit
def median_inplace(v):
    """``float(np.median(v))`` of a non-empty 1-D float32 or float64 array without NaNs;
    overwrites ``v`` (pass a copy to keep it)."""
    n = v.shape[0]
    lower, upper = select_pair(v, n >> 1)
    if n & 1:
        return float(upper)
    return float((lower + upper) / v.dtype.type(2.0))
