"""The discs' images' analytic pose derivatives (``model.disc_images_with_derivatives``)
against central differences of the model itself (``model.disc_images``)."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
from tofpose.sim.bench import R_FACING
from tofpose.stages.pixelfit.constants import ROTATION_STEP_RAD, TRANSLATION_STEP_MM
from tofpose.stages.pixelfit.model import (
    Discs,
    build_windows,
    disc_images,
    disc_images_with_derivatives,
    predicted_rims,
)

CAM = CameraModel()
CAT = paper_target()
#: the fit's central-difference steps (``fit._pose_columns_numeric``)
STEPS = np.array([ROTATION_STEP_RAD] * 3 + [TRANSLATION_STEP_MM] * 3)


def _central_differences(T, discs, win, args, steps):
    """(coverage (K, P, 6), phasor (K, P, 6), plate (P, 6)) by central differences."""
    cols = []
    for i, h in enumerate(steps):
        e = np.zeros(6)
        e[i] = h
        out = [
            disc_images(
                Rotation.from_rotvec(sign * e[:3]).as_matrix() @ T.R,
                T.t_mm + sign * e[3:],
                discs,
                win,
                **args,
            )
            for sign in (1.0, -1.0)
        ]
        cols.append([(getattr(out[0], f) - getattr(out[1], f)) / (2 * h) for f in _FIELDS])
    return [np.stack([c[j] for c in cols], axis=-1) for j in range(3)]


_FIELDS = ("coverage", "phasor", "plate_phasor")


def _relative_errors(analytic, numeric):
    """Per direction: the largest and the RMS error over the largest |derivative|."""
    a = analytic.reshape(-1, 6)
    n = numeric.reshape(-1, 6)
    scale = np.maximum(np.abs(a).max(axis=0), 1e-300)
    err = np.abs(a - n)
    return err.max(axis=0) / scale, np.sqrt(np.mean(err**2, axis=0)) / scale


@pytest.mark.parametrize(
    ("range_mm", "tilt_deg", "across_mm"),
    [(1000.0, 0.0, 40.0), (3000.0, 15.0, -60.0), (8000.0, 30.0, 150.0), (1000.0, 22.0, 100.0)],
)
def test_analytic_derivatives_are_the_models_central_differences(range_mm, tilt_deg, across_mm):
    """Discs at 1, 3 and 8 m tilted 0-30 deg; the last case cuts disc 8 at the image's
    right edge.

    At the fit's steps the central differences are not exact: a sub-cell's box integral is
    piecewise quadratic in the rim's distance s, only once differentiable, and near an
    axis-aligned rim it turns from flat to its full slope within 2 a, less than the
    step's move along s (3e-3 px for 1e-2 mm at 1 m): a step across that turn sees a
    kink, and the pixel's difference errs by a part of one sub-cell's slope. Limits: 5e-2
    of each direction's largest derivative, RMS 1e-4 (measured worst 1.2e-2 on the cut
    disc at 1 m, 1e-8 to 6e-5 at 8 m, RMS <= 7e-5); the plate's range is smooth: 1e-6
    (measured 5e-10). That the error is the differences' and not the derivatives' is the
    second check: at 1000 times smaller steps they agree to 1e-6 (measured <= 1.1e-7;
    the plate's differences are rounding there, so not compared)."""
    R = rotation_from_euler_deg(tilt_deg / 2, -tilt_deg, 5) @ R_FACING
    T = RigidTransform(R, np.array([across_mm, -25.0, range_mm]))
    discs = Discs.from_catalog(CAT, CAT.ids)
    win = build_windows(np.zeros(CAM.shape), np.zeros(CAM.shape), CAM, discs, T.R, T.t_mm)
    args = dict(mm_per_radian=3979.0, reference_mm=range_mm)
    images, d = disc_images_with_derivatives(T.R, T.t_mm, discs, win, **args)
    rim = (images.coverage > 0) & (images.coverage < 1)
    assert rim.sum() > 50
    if across_mm == 100.0:  # disc 8 crosses the image's edge: part of it has no window
        u = predicted_rims(CAM, T.R, T.t_mm, discs)[7, :, 0]
        assert u.min() < CAM.width - 1 < u.max()
        assert np.any(rim[7])
    analytic = (d.coverage, d.phasor, d.plate_phasor)
    at_fit_steps = _central_differences(T, discs, win, args, STEPS)
    for name, a, n in zip(_FIELDS, analytic, at_fit_steps, strict=True):
        worst, rms = _relative_errors(a, n)
        limit = 1e-6 if name == "plate_phasor" else 5e-2
        assert np.all(worst < limit), (name, worst)
        assert np.all(rms < 1e-4), (name, rms)
    finer = _central_differences(T, discs, win, args, STEPS / 1000)
    for name, a, n in zip(_FIELDS[:2], analytic[:2], finer[:2], strict=True):
        worst, _ = _relative_errors(a, n)
        assert np.all(worst < 1e-6), (name, worst)
