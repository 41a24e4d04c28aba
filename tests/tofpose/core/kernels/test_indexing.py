"""Flat index -> (row, col) without integer division, against numpy's divmod."""

import numpy as np
import pytest

from tofpose.core.kernels.indexing import row_col


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


def test_runs_split_a_pixel_list_at_gaps_and_row_ends():
    from tofpose.core.kernels.indexing import run_end

    width = 10
    # row 0: columns 2-4 and 8-9; row 1: columns 0-1 (consecutive with row 0's end, but
    # another row); row 3: column 5
    flat = np.array([2, 3, 4, 8, 9, 10, 11, 35], np.int64)
    runs, i = [], 0
    while i < len(flat):
        r, c = row_col(flat[i], width, 1.0 / width)
        e = run_end(flat, i, len(flat), width - c)
        runs.append(flat[i:e].tolist())
        i = e
    assert runs == [[2, 3, 4], [8, 9], [10, 11], [35]]
    assert run_end(flat, 0, 2, width) == 2  # never past the end given
