"""bench/rim_sampling.py: it names the point-sampling grid our own renderer used for a
recording's rims (``SensorModel.supersampling``), finds none on finely sampled frames,
and refuses a recording without truth."""

from __future__ import annotations

import pytest

from bench.rim_sampling import rim_sampling
from tests.conftest import facing_pose, render
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import paper_target
from tofpose.io.recording import RecordingError, RecordingWriter, open_recording
from tofpose.sim.render import SensorModel

POSES = [
    facing_pose(2500.0, 8.0, -5.0, 3.0, (40.0, -30.0)),
    facing_pose(3500.0, -6.0, 10.0, -2.0, (-90.0, 50.0)),
]


def _recording(path, supersampling: int, *, truth: bool = True):
    sensor = SensorModel(noise=False, supersampling=supersampling)
    with RecordingWriter(path, CameraModel(), paper_target(), with_truth=truth) as w:
        for i, T in enumerate(POSES):
            f = render(T, noise=False, sensor=sensor)
            if truth:
                w.append(f.gray, f.distance_mm, 0.1 * i, T.R, T.t_mm)
            else:
                w.append(f.gray, f.distance_mm, 0.1 * i)
    return open_recording(path)


@pytest.mark.parametrize("grid", [1, 2, 3, 4])
def test_a_coarse_point_sampling_grid_is_named(tmp_path, grid):
    found = rim_sampling(_recording(tmp_path / f"s{grid}.h5", grid))
    assert found.n_poses == 2 and found.n_pixels > 50
    assert found.grid == grid, found.describe()
    # a coverage quantised to 1/S^2 is off the exact area by up to half a step
    assert 0.1 / grid**2 < found.coverage_error_rms < 0.6 / grid**2


def test_finely_sampled_rims_have_no_grid_and_a_small_coverage_error(tmp_path):
    found = rim_sampling(_recording(tmp_path / "fine.h5", 32))
    assert found.grid is None, found.describe()
    assert found.coverage_error_rms < 0.01
    assert min(found.distance_to_level.values()) > 0.2  # 0.25: not quantised


def test_a_recording_without_truth_is_refused(tmp_path):
    with pytest.raises(RecordingError, match="needs /truth and a catalog"):
        rim_sampling(_recording(tmp_path / "no-truth.h5", 3, truth=False))
