"""The 3-D scene's ground grid, rulers in metres and pose trail: the pure model
(``scene_model``) against hand-checked values, and the nodes in a running scene."""

from __future__ import annotations

import numpy as np
import pytest

from backend.services.live.scene_model import (
    GROUND_DROP_M,
    PoseTrail,
    nice_step_m,
    scale_marks,
    scale_segments,
    scene_extent_m,
)
from tests.backend.conftest import make_settings, running_app, wait_for


@pytest.mark.parametrize(
    ("extent_m", "step_m"), [(2.0, 0.2), (3.0, 0.5), (10.0, 1.0), (16.0, 2.0), (40.0, 5.0)]
)
def test_the_scale_step_is_1_2_or_5_times_a_power_of_ten_and_at_most_10_ticks(extent_m, step_m):
    assert nice_step_m(extent_m) == pytest.approx(step_m)
    assert extent_m / step_m <= 10


@pytest.mark.parametrize("extent_m", [0.0, -1.0, float("nan")])
def test_a_scale_without_a_positive_extent_is_refused(extent_m):
    with pytest.raises(ValueError, match="positive length"):
        nice_step_m(extent_m)


def test_the_extent_reaches_past_the_farthest_point_in_whole_metres():
    assert scene_extent_m(np.array([[0.0, 0.0, 13.0], [0.1, -0.2, 15.02]])) == 17.0
    assert scene_extent_m(np.array([[-4.4, 0.0, 1.0]])) == 6.0  # lateral reach counts
    assert scene_extent_m(np.zeros((1, 3))) == 2.0


def test_the_rulers_are_labelled_in_metres_on_the_ground():
    marks, step = scale_marks(16.0)
    assert step == 2.0
    along_z = [m for m in marks if m.position_m[0] == 0.0]
    assert [m.text for m in along_z] == [f"{z} m" for z in range(0, 17, 2)]
    assert [m.position_m[2] for m in along_z] == list(range(0, 17, 2))
    across = sorted(m.position_m[0] for m in marks if m.position_m[0] != 0.0)
    assert across == [-8.0, -6.0, -4.0, -2.0, 2.0, 4.0, 6.0, 8.0]
    assert {m.position_m[1] for m in marks} == {GROUND_DROP_M}
    segments = scale_segments(marks, 16.0)
    assert segments.shape == (2 + len(marks), 2, 3)
    np.testing.assert_allclose(segments[0], [[0, GROUND_DROP_M, 0], [0, GROUND_DROP_M, 16]])


def test_the_trail_keeps_the_newest_poses_in_order_and_clears():
    trail = PoseTrail(max_poses=3)
    for k in range(5):
        trail.add(np.array([k, 0.0, 10.0 + k]))
    np.testing.assert_array_equal(trail.points_m[:, 0], [2, 3, 4])
    seg = trail.segments_m()
    assert seg.shape == (2, 2, 3)
    np.testing.assert_array_equal(seg[:, 0, 0], [2, 3])
    np.testing.assert_array_equal(seg[:, 1, 0], [3, 4])
    trail.clear()
    assert len(trail) == 0 and trail.segments_m().shape == (0, 2, 3)
    with pytest.raises(ValueError, match="finite"):
        trail.add(np.array([np.nan, 0, 0]))
    with pytest.raises(ValueError, match="at least 2"):
        PoseTrail(max_poses=1)


@pytest.fixture
def scene(tmp_path):
    settings = make_settings(tmp_path / "data", viser=True, viser_port=0, sim_time_scale=5.0)
    with running_app(settings) as client:
        yield client.app.state.tofpose.scene


def test_a_running_scene_has_the_grid_the_rulers_and_a_trail_it_can_clear(scene):
    wait_for(lambda: scene.updates >= 4, 20.0, "4 scene updates")
    names = set(scene.server.scene._handle_from_node_name)
    assert {"/ground/grid", "/ground/scale", "/trail"} <= names
    assert {"/ground/scale/axis_x", "/ground/scale/axis_z"} <= names
    # the simulated bench: camera at 13 m on the rail, target 2 m ahead: 15 m (+- the
    # estimate's noise) + 1 m, rounded up
    assert scene._extent_m in (16.0, 17.0)
    labels = sorted(n for n in names if n.startswith("/ground/scale/label_"))
    assert len(labels) == len(scale_marks(scene._extent_m)[0])
    points = scene.trail.points_m
    assert len(points) >= 3 and scene.trail_node.visible
    np.testing.assert_allclose(points[-1], scene.estimate.position, atol=0.05)
    np.testing.assert_allclose(points, [[0.0, 0.0, 15.0]] * len(points), atol=0.05)
    scene.clear_trail()
    assert len(scene.trail) <= 1 and not (len(scene.trail) == 0 and scene.trail_node.visible)
    wait_for(lambda: len(scene.trail) >= 2, 20.0, "the trail to grow again")
    assert scene.trail_node.visible
