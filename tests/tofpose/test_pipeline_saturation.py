"""Saturated reflectors say so (issue 49, item 2): ``MatchedReflector.saturated`` and the
refused frame's reason, against the simulator's rendered gray image."""

import pytest

from tests.conftest import facing_pose, render
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target
from tofpose.config import TrackingConfig
from tofpose.sim.render import RenderedFrame, SensorModel
from tofpose.sim.scene import FIRST_DISC

SATURATION_CLAUSE = (
    "; 2 candidates saturate (gray at full scale 4095): lower the integration time or turn "
    "auto exposure on"
)


def fixed_exposure(integration_time_us: float) -> SensorModel:
    return SensorModel(auto_exposure=False, integration_time_us=integration_time_us)


def saturated_truth(frame: RenderedFrame, camera: CameraModel) -> dict[int, bool]:
    """Catalog id -> whether a pixel whose centre the simulator saw on that reflector's
    disc reads at or above full scale, for every reflector with such a pixel."""
    ids = paper_target().ids
    truth = {}
    for k, catalog_id in enumerate(ids.tolist()):
        on_disc = frame.surface_id == FIRST_DISC + k
        if on_disc.any():
            truth[catalog_id] = bool((frame.gray[on_disc] >= camera.full_scale_counts).any())
    return truth


@pytest.mark.parametrize(
    ("integration_time_us", "n_saturated"),
    [
        (800.0, 2),  # the two nearest large discs (7, 8) over full scale, the rest below
        (1500.0, 5),  # the large ones and 4; 1-3 (small, farther) still below
    ],
)
def test_matched_reflectors_are_saturated_exactly_where_their_pixels_reach_full_scale(
    integration_time_us, n_saturated
):
    camera = CameraModel()
    frame = render(
        facing_pose(2000.0, yaw_deg=25.0), seed=1, sensor=fixed_exposure(integration_time_us)
    )
    truth = saturated_truth(frame, camera)
    assert sum(truth.values()) == n_saturated  # a frame with both kinds
    result = PosePipeline(camera, paper_target()).process(frame.gray, frame.distance_mm)
    assert result.ok, result.reason
    flags = {m.catalog_id: m.saturated for m in result.matched}
    assert len(flags) == len(truth)
    assert flags == truth


def test_no_reflector_is_saturated_under_auto_exposure():
    camera = CameraModel()
    frame = render(facing_pose(2000.0, yaw_deg=25.0), seed=1)
    assert not any(saturated_truth(frame, camera).values())
    result = PosePipeline(camera, paper_target()).process(frame.gray, frame.distance_mm)
    assert result.ok and result.n_matched == 8, result.reason
    assert not any(m.saturated for m in result.matched)


def test_tracked_frames_flag_saturated_reflectors_too():
    # tracking leaves out 7 and 8 here (their windows overlap); at 1500 us 4-6 saturate
    camera = CameraModel()
    config = PipelineConfig(tracking=TrackingConfig(enabled=True))
    pipe = PosePipeline(camera, paper_target(), config)
    T = facing_pose(2000.0, yaw_deg=25.0)
    tracked = 0
    for seed in range(4):
        frame = render(T, seed=seed, sensor=fixed_exposure(1500.0))
        result = pipe.process(frame.gray, frame.distance_mm, seed / 10)
        assert result.ok, result.reason
        truth = saturated_truth(frame, camera)
        flags = {m.catalog_id: m.saturated for m in result.matched}
        assert flags == {i: truth[i] for i in flags}
        if result.mode == "tracking":
            tracked += 1
            assert set(flags.values()) == {True, False}, flags
    assert tracked >= 2


def test_a_refused_frame_counts_its_saturated_candidates_and_says_what_to_do():
    # two small reflectors (1, 2) in view: too few for a pose, whatever the exposure
    camera, catalog = CameraModel(), paper_target()
    T = facing_pose(1500.0, offset_mm=(900.0, -450.0))
    reasons = {}
    for t_us in (300.0, 4000.0):
        frame = render(T, seed=1, sensor=fixed_exposure(t_us))
        truth = saturated_truth(frame, camera)
        assert sorted(truth) == [1, 2]
        result = PosePipeline(camera, catalog).process(frame.gray, frame.distance_mm)
        assert not result.ok
        reasons[t_us] = (result.reason, sum(truth.values()))
    below, n_below = reasons[300.0]
    over, n_over = reasons[4000.0]
    assert (n_below, n_over) == (0, 2)
    assert "saturate" not in below
    assert below.startswith("found 2 candidate reflector(s)")
    # the reason the frame had before, and the clause after it
    assert over == below + SATURATION_CLAUSE
