import numpy as np
import pytest

from tofpose.core.robust import median_1d


@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int32, np.int64])
def test_median_1d_is_numpys_median(dtype):
    rng = np.random.default_rng(0)
    for n in range(1, 40):
        a = (rng.normal(size=n) * 1000).astype(dtype)
        assert median_1d(a) == float(np.median(a))
    assert median_1d(np.array([3.0, 1.0])) == 2.0 and median_1d(np.array([5])) == 5.0
