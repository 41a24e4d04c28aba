"""The assignment kernel against SciPy's ``linear_sum_assignment``: the same pairs, on
square and rectangular matrices both ways, with and without ties."""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment as scipy_lsa

from tofpose.stages.matching.kernels.assignment import linear_sum_assignment


def _matrices(rng):
    for _ in range(3000):
        nr, nc = rng.integers(1, 13, 2)
        kind = rng.integers(4)
        if kind == 0:  # distances, as the hypothesis loops give them
            c = np.linalg.norm(
                rng.normal(0, 50, (nr, 1, 3)) - rng.normal(0, 50, (1, nc, 3)), axis=-1
            )
        elif kind == 1:  # small integers: many ties and several optimal answers
            c = rng.integers(0, 4, (nr, nc)).astype(float)
        elif kind == 2:  # constant
            c = np.full((nr, nc), 7.0)
        else:  # negative and positive
            c = rng.normal(0, 1, (nr, nc))
        yield c


def test_the_same_pairs_as_scipy():
    rng = np.random.default_rng(11)
    for c in _matrices(rng):
        rows, cols = linear_sum_assignment(c)
        want_rows, want_cols = scipy_lsa(c)
        np.testing.assert_array_equal(rows, want_rows)
        np.testing.assert_array_equal(cols, want_cols)


def test_an_empty_matrix_has_no_pairs():
    for shape in ((0, 4), (3, 0)):
        rows, cols = linear_sum_assignment(np.zeros(shape))
        assert len(rows) == len(cols) == 0
