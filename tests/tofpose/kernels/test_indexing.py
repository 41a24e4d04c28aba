"""Flat index -> (row, col) without integer division, against numpy's divmod."""

import numpy as np
import pytest

from tofpose.kernels.indexing import row_col


@pytest.mark.parametrize("width", [1, 3, 7, 320, 640, 1280, 4097])
def test_row_col_equals_divmod_over_whole_images_and_at_row_ends(width):
    rows = 2048
    every = np.arange(rows * width, dtype=np.int64)[:: max(1, width // 7)]
    ends = np.arange(1, rows, dtype=np.int64) * width  # the first pixel of each row
    for p in np.concatenate([every, ends, ends - 1]):
        assert row_col(p, width, 1.0 / width) == divmod(int(p), width)


def test_row_col_exact_for_indices_far_beyond_any_image():
    width = 3001
    for p in [2**40 + 17, 2**45 - 1, 2**45, 2**49 - 1]:
        p = (p // width) * width  # a row start: the hardest case, 0.5 / width from a row
        for q in (p - 1, p, p + 1):
            assert row_col(q, width, 1.0 / width) == divmod(q, width)
