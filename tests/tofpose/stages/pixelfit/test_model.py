import numpy as np
import pytest

from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.core.geometry import RigidTransform
from tofpose.sim.bench import R_FACING
from tofpose.stages.pixelfit.model import Discs, build_windows, disc_images


def test_coverage_sums_to_the_projected_disc_area():
    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(R_FACING, np.array([0.0, 0.0, 2000.0]))
    discs = Discs.from_catalog(cat, cat.ids)
    h, w = cam.shape
    win = build_windows(np.zeros((h, w)), np.zeros((h, w)), cam, discs, T.R, T.t_mm)
    images = disc_images(T.R, T.t_mm, discs, win, mm_per_radian=4000.0, reference_mm=2000.0)
    z = (T.apply(discs.centres_mm))[:, 2]
    area = np.pi * (discs.radii_mm * cam.fx / z) ** 2  # a facing disc near the axis
    np.testing.assert_allclose(images.coverage.sum(axis=1), area, rtol=3e-3)


def test_discs_name_a_missing_or_repeated_id():
    with pytest.raises(ValueError, match="not in the catalog"):
        Discs.from_catalog(paper_target(), [1, 2, 99])
    with pytest.raises(ValueError, match="twice"):
        Discs.from_catalog(paper_target(), [1, 1, 2])


@pytest.mark.parametrize(("range_mm", "tilt_deg"), [(1000.0, 0.0), (3000.0, 25.0), (8000.0, 10.0)])
def test_sub_cells_taking_their_pixels_bearing_derivatives_move_the_coverage_negligibly(
    range_mm, tilt_deg
):
    """``build_windows`` gives a sub-cell its pixel's bearing derivatives (each of its own
    costs four more bearings): the images against those with every sub-cell's own
    derivatives differ by under 1e-4 of a pixel's coverage (7.7e-5 at 1 m, 4e-5 at 3
    and 8 m; a rim pixel's shot noise is ~2e-2 of its coverage), off axis and on a
    distorting lens too."""
    from dataclasses import replace

    from tofpose.core.geometry import rotation_from_euler_deg
    from tofpose.stages.pixelfit.model import _bearings_with_derivatives

    cat = paper_target()
    for cam in (CameraModel(), replace(CameraModel(), dist=(-0.25, 0.1, 0.001, -0.001, 0.0))):
        R = rotation_from_euler_deg(tilt_deg, -tilt_deg / 2, 5.0) @ R_FACING
        T = RigidTransform(R, np.array([0.25 * range_mm, -0.15 * range_mm, range_mm]))
        discs = Discs.from_catalog(cat, cat.ids)
        win = build_windows(np.zeros(cam.shape), np.zeros(cam.shape), cam, discs, T.R, T.t_mm)
        n_sub = win.sample_bearings.shape[1]
        sample_uv = np.column_stack([win.cols, win.rows])[:, None, :] + _sub_cell_offsets(
            win.subsamples
        )
        _, own_u, own_v = _bearings_with_derivatives(cam, sample_uv.reshape(-1, 2))
        exact = replace(
            win,
            sample_dbdu=own_u.reshape(-1, n_sub, 3),
            sample_dbdv=own_v.reshape(-1, n_sub, 3),
        )
        args = {"mm_per_radian": 4000.0, "reference_mm": range_mm}
        fast = disc_images(T.R, T.t_mm, discs, win, **args)
        slow = disc_images(T.R, T.t_mm, discs, exact, **args)
        rim = (slow.coverage > 0) & (slow.coverage < 1)
        assert rim.sum() > 50
        assert np.abs(fast.coverage - slow.coverage).max() < 1e-4
        assert np.abs(fast.phasor - slow.phasor).max() < 1e-4


def _sub_cell_offsets(s):
    """(S * S, 2) the sub-cells' centres' offsets from their pixel's, px (``build_windows``'
    grid)."""
    offs = (np.arange(s) + 0.5) / s - 0.5
    ox, oy = np.meshgrid(offs, offs)
    return np.column_stack([ox.ravel(), oy.ravel()])


def test_plate_fraction_is_the_plates_projected_area_and_edge():
    """A facing plate off axis at 4 m: pixels wholly inside are 1, those beyond 0, the
    fractions sum to the plate's projected area within its part of the image, and a
    pixel its edge halves is near 1/2."""
    from tofpose.stages.pixelfit.model import plate_fraction

    cam, cat = CameraModel(), paper_target()
    T = RigidTransform(R_FACING, np.array([600.0, 0.0, 4000.0]))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    uv = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    s = 4
    offs = (np.arange(s) + 0.5) / s - 0.5
    grid = np.stack(np.meshgrid(offs, offs), axis=-1).reshape(-1, 2)
    rays = cam.bearings((uv[:, None] + grid[None]).reshape(-1, 2)).reshape(len(uv), s * s, 3)
    f = plate_fraction(rays, T.R, T.t_mm, cat.plate_size_mm).reshape(cam.shape)
    w, h = cat.plate_size_mm
    assert f.sum() == pytest.approx(w * h * (cam.fx / 4000.0) ** 2, rel=0.01)
    centre = cam.project(np.array([[600.0, 0.0, 4000.0]]))[0]
    assert f[int(round(centre[1])), int(round(centre[0]))] == 1.0
    assert f[0, 0] == 0.0 and f[-1, -1] == 0.0
    assert set(np.unique(f)) > {0.0, 1.0}  # the edge's pixels in between
