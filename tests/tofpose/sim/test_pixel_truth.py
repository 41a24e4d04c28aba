"""The ray-cast true distances against the renderer's own noiseless distances."""

from __future__ import annotations

import numpy as np

from tests.conftest import facing_pose
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.sim.pixel_truth import true_pixel_distances
from tofpose.sim.render import SensorModel, render_frame
from tofpose.sim.scene import TargetScene

CAM = CameraModel()


def test_true_pixel_distances_match_the_renderers_noiseless_truth():
    T = facing_pose(2000.0, yaw_deg=5.0)
    truth = true_pixel_distances(CAM, paper_target(), T, reflectors_only=False)
    f = render_frame(CAM, TargetScene(), T, SensorModel(noise=False), None)
    known = np.isfinite(truth)
    assert known.sum() > 10_000
    np.testing.assert_allclose(truth[known], f.true_distance_mm[known], atol=0.01)
