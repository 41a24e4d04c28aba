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
    """A plate turned 90 deg about its normal, off axis at 4 m: its 990 mm width spans
    the image's rows, its 550 mm height the columns; each row through it sums to the
    height in px (its two edge pixels' fractions included, to 0.3 px), each column to
    the width; pixels wholly inside are 1 and those beyond 0."""
    from tofpose.core.geometry import rotation_from_euler_deg
    from tofpose.stages.pixelfit.model import plate_fraction

    cam, cat = CameraModel(), paper_target()
    R = R_FACING @ rotation_from_euler_deg(0.0, 0.0, 90.0)
    T = RigidTransform(R, np.array([80.0, -40.0, 4000.0]))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    uv = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    s = 8
    offs = (np.arange(s) + 0.5) / s - 0.5
    grid = np.stack(np.meshgrid(offs, offs), axis=-1).reshape(-1, 2)
    rays = cam.bearings((uv[:, None] + grid[None]).reshape(-1, 2)).reshape(len(uv), s * s, 3)
    f = plate_fraction(rays, T.R, T.t_mm, cat.plate_size_mm).reshape(cam.shape)
    width_mm, height_mm = cat.plate_size_mm
    px_per_mm = cam.fx / 4000.0
    centre = cam.project(np.array([[80.0, -40.0, 4000.0]]))[0]
    row, col = int(round(centre[1])), int(round(centre[0]))
    assert f[row].sum() == pytest.approx(height_mm * px_per_mm, abs=0.3)
    assert f[:, col].sum() == pytest.approx(width_mm * px_per_mm, abs=0.3)
    assert f[row, col] == 1.0
    assert f[0, 0] == 0.0 and f[-1, -1] == 0.0
    assert np.any((f[row] > 0.1) & (f[row] < 0.9))  # the edges' pixels in between


def test_plate_fraction_follows_the_plates_projected_corners_at_any_pose():
    """At a pose turned about every axis (``R`` not its transpose), the pixels whose
    centres lie over 1 px inside the polygon of the plate's projected corners are 1,
    those over 1 px outside it 0."""
    import cv2

    from tofpose.core.geometry import rotation_from_euler_deg
    from tofpose.stages.pixelfit.model import plate_fraction

    cam, cat = CameraModel(), paper_target()
    R = R_FACING @ rotation_from_euler_deg(15.0, -25.0, 35.0)
    assert not np.allclose(R, R.T)
    t = np.array([150.0, 60.0, 3500.0])
    w, h = np.asarray(cat.plate_size_mm) / 2
    corners = np.array([[-w, -h, 0.0], [w, -h, 0.0], [w, h, 0.0], [-w, h, 0.0]])
    polygon = cam.project(corners @ R.T + t).astype(np.float32)
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    uv = np.column_stack([u.ravel(), v.ravel()]).astype(float)
    rays = cam.bearings(uv)[:, None, :]  # one sub-cell: the pixel's centre
    f = plate_fraction(rays, R, t, cat.plate_size_mm)
    signed = np.array([cv2.pointPolygonTest(polygon, (float(a), float(b)), True) for a, b in uv])
    assert np.sum(signed > 1) > 1000 and np.sum(signed < -1) > 1000
    assert np.all(f[signed > 1] == 1.0) and np.all(f[signed < -1] == 0.0)
