"""The compiled discs' images (``kernels.images``) against the NumPy model."""

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.stages.pixelfit.model import Discs, build_windows, disc_images


@pytest.mark.parametrize("range_mm", [1500.0, 6000.0])
def test_compiled_images_equal_the_numpy_reference(range_mm):
    """The compiled kernel and the NumPy model are one arithmetic: a tilted target, every
    disc, the window's pixels and sub-cells."""
    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(
        rotation_from_euler_deg(8, -12, 20) @ R_FACING, np.array([40, -25, range_mm])
    )
    discs = Discs.from_catalog(cat, cat.ids)
    h, w = cam.shape
    win = build_windows(np.zeros((h, w)), np.zeros((h, w)), cam, discs, T.R, T.t_mm)
    args = dict(mm_per_radian=3979.0, reference_mm=range_mm)
    fast = disc_images(T.R, T.t_mm, discs, win, compiled=True, **args)
    slow = disc_images(T.R, T.t_mm, discs, win, compiled=False, **args)
    assert fast.coverage.sum() > 0 and np.any((fast.coverage > 0) & (fast.coverage < 1))
    np.testing.assert_allclose(fast.coverage, slow.coverage, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.phasor, slow.phasor, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.plate_phasor, slow.plate_phasor, rtol=0, atol=0)
