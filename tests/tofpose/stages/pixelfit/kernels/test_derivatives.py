"""The compiled images' pose derivatives (``kernels.derivatives``) against their NumPy
reference (``reference.derivatives``) and against the compiled images without them."""

import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.stages.pixelfit.model import (
    Discs,
    build_windows,
    disc_images,
    disc_images_with_derivatives,
)


@pytest.mark.parametrize(
    ("range_mm", "tilt_deg", "across_mm"),
    [(1000.0, 0.0, 40.0), (3000.0, 15.0, -60.0), (8000.0, 30.0, 150.0), (1000.0, 22.0, 100.0)],
)
def test_compiled_derivatives_equal_the_numpy_reference(range_mm, tilt_deg, across_mm):
    """One arithmetic: every disc, the window's pixels and sub-cells (the last case cuts
    disc 8 at the image's right edge)."""
    cam, cat = CameraModel(), paper_target()
    R = rotation_from_euler_deg(tilt_deg / 2, -tilt_deg, 5) @ R_FACING
    T = RigidTransform(R, np.array([across_mm, -25.0, range_mm]))
    discs = Discs.from_catalog(cat, cat.ids)
    win = build_windows(np.zeros(cam.shape), np.zeros(cam.shape), cam, discs, T.R, T.t_mm)
    args = dict(mm_per_radian=3979.0, reference_mm=range_mm)
    fast, d_fast = disc_images_with_derivatives(T.R, T.t_mm, discs, win, compiled=True, **args)
    slow, d_slow = disc_images_with_derivatives(T.R, T.t_mm, discs, win, compiled=False, **args)
    plain = disc_images(T.R, T.t_mm, discs, win, **args)
    rim = (fast.coverage > 0) & (fast.coverage < 1)
    assert rim.sum() > 50 and np.all(np.abs(d_fast.coverage[rim]).max(axis=1) > 0)
    # the images are the no-derivative kernel's
    np.testing.assert_allclose(fast.coverage, plain.coverage, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.phasor, plain.phasor, rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.plate_phasor, plain.plate_phasor, rtol=0, atol=1e-12)
    np.testing.assert_allclose(slow.coverage, plain.coverage, rtol=0, atol=1e-12)
    # derivatives: to 1e-10 of each direction's largest (per rad and per mm differ by
    # 1e3); rounding in the box integral's 1/(4 a b) on near axis-aligned rims leaves
    # ~1e-12 of it. A facing plate's phasor does not move with a roll or a sideways
    # step: both are 0 there (1e-15: rounding)
    for fast_d, slow_d in (
        (d_fast.coverage, d_slow.coverage),
        (d_fast.phasor, d_slow.phasor),
        (d_fast.plate_phasor, d_slow.plate_phasor),
    ):
        scale = np.abs(slow_d).reshape(-1, 6).max(axis=0)
        err = np.abs(fast_d - slow_d).reshape(-1, 6).max(axis=0)
        assert np.all(err <= 1e-10 * scale + 1e-15), (err, scale)
