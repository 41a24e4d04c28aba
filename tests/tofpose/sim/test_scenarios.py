import numpy as np
import pytest

from tofpose.sim.scenarios import SCENARIOS, get_scenario, run_scenario


def test_unknown_scenario_lists_the_names():
    with pytest.raises(ValueError, match="unknown scenario 'nope'; choose one of stability-697"):
        get_scenario("nope")


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_every_scenario_yields_frames_with_truth(name):
    frames = list(run_scenario(get_scenario(name), 3, seed=1))
    assert len(frames) == 3
    assert all(f.frame.gray.shape == (240, 320) for f in frames)
    times = [f.time_s for f in frames]
    assert times == sorted(times)
    assert all(np.isfinite(f.T_lab_truth.t_mm).all() for f in frames)


def test_range_sweep_spans_the_operating_range():
    sc = get_scenario("range-sweep")
    frames = list(run_scenario(sc, len(sc.setpoints), seed=0))
    z = [f.T_true.t_mm[2] for f in frames]
    assert min(z) < 400 and max(z) > 14000


def test_same_seed_same_recording():
    a = next(run_scenario(get_scenario("clutter"), 1, seed=4))
    b = next(run_scenario(get_scenario("clutter"), 1, seed=4))
    np.testing.assert_array_equal(a.frame.gray, b.frame.gray)
