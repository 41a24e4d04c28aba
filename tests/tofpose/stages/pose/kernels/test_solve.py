"""§5's completion step (``kernels.solve.complete_pairs``) against its NumPy statement
(``tofpose.stages.pose.reference.solve.complete_pairs``), and the shared solve finding a pose whose
completion recovered the reflectors annealing left out."""

from __future__ import annotations

import numpy as np

from tofpose.core.geometry import rotation_from_euler_deg
from tofpose.stages.pose.kernels.solve import complete_pairs
from tofpose.stages.pose.reference.solve import complete_pairs as reference_complete_pairs


def test_completion_equals_the_numpy_statement_and_restores_dropped_pairs():
    rng = np.random.default_rng(3)
    restored = 0
    for _ in range(300):
        e = int(rng.integers(4, 10))
        xyz = rng.uniform(-200, 200, (e, 3))
        R = rotation_from_euler_deg(*rng.uniform(-30, 30, 3))
        t = np.array([10.0, -40.0, 3000.0])
        order = rng.permutation(e)  # blob k shows reflector order[k]
        y = xyz[order] @ R.T + t + rng.normal(0, 1.0, (e, 3))
        spurious = rng.uniform(-300, 300, (int(rng.integers(0, 3)), 3)) + t
        y = np.vstack((y, spurious))
        n_matched = int(rng.integers(3, e + 1))
        k_idx = np.arange(n_matched)
        i_idx = order[:n_matched].copy()
        got = complete_pairs(y, k_idx, i_idx, xyz, R, t, 8.0)
        want = reference_complete_pairs(y, k_idx, i_idx, xyz, R, t, 8.0)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
        # every blob of a reflector is back with its own reflector
        assert dict(zip(got[0].tolist(), got[1].tolist(), strict=True)) == {
            k: int(order[k]) for k in range(e)
        }
        restored += len(got[0]) - n_matched
    assert restored > 100
