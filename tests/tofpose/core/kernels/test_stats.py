"""The kernels' selection and median against NumPy, on the inputs that break
quickselects: ties, constant, sorted and reversed arrays, both float widths."""

from __future__ import annotations

import numpy as np
import pytest

from tofpose.core.kernels.stats import median_inplace, select_pair


def _arrays(rng, dtype):
    for n in (1, 2, 3, 4, 5, 17, 24, 25, 26, 256, 1701, 4096):
        noisy = rng.normal(2000.0, 5.0, n).astype(dtype)
        yield noisy
        yield np.round(noisy)  # many ties
        yield np.full(n, 3.0, dtype)
        yield np.sort(noisy)
        yield np.sort(noisy)[::-1].copy()
        yield np.tile(np.array([1.0, 2.0], dtype), n)[:n]  # two values alternating
        # large arrays are bracketed from a regular sample first: a sample that sees only
        # outliers (the bracket misses, the quickselect takes the whole array), heavy
        # tails and two modes
        spiked = noisy.copy()
        spiked[(2 * np.arange(31) + 1) * n // 62] = 1e6
        yield spiked
        yield np.abs(rng.standard_cauchy(n)).astype(dtype)
        yield np.where(rng.random(n) < 0.5, noisy, noisy + 300).astype(dtype)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_median_is_numpy_median_exactly(dtype):
    rng = np.random.default_rng(0)
    for v in _arrays(rng, dtype):
        assert median_inplace(v.copy()) == float(np.median(v))  # bit for bit


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_select_pair_gives_the_two_order_statistics(dtype):
    rng = np.random.default_rng(1)
    for v in _arrays(rng, dtype):
        ranked = np.sort(v)
        n = len(v)
        for k in {0, 1, n // 2, n // 2 + 1, n // 3, n - 1, int(rng.integers(0, n))} - {n}:
            lower, upper = select_pair(v.copy(), k)
            assert upper == ranked[k]
            assert lower == (ranked[k - 1] if k > 0 else -np.inf)
