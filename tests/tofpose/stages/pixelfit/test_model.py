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
