"""The simulated bench: motion artefacts only while the table moves."""

import numpy as np

from tofpose.core.catalog import paper_target
from tofpose.sim.bench import LabGeometry, SimulatedBench
from tofpose.sim.render import SensorModel
from tofpose.sim.scene import TargetScene
from tofpose.sim.turntable import Turntable


def _bench(**sensor) -> SimulatedBench:
    return SimulatedBench(
        scene=TargetScene(paper_target()),
        geometry=LabGeometry(target_distance_mm=3000.0),
        turntable=Turntable(),
        sensor=SensorModel(**sensor),
    )


def test_subframes_only_while_the_table_moves():
    bench = _bench()
    T, _, _ = bench.poses_at(0.0)
    assert bench.subframe_poses(0.0, T) is None  # at rest: one static render
    bench.turntable.move_to({"yaw": 10.0}, 0.0)
    T, _, _ = bench.poses_at(0.3)
    poses = bench.subframe_poses(0.3, T)
    assert poses is not None and len(poses) == 4
    period = bench.sensor.subframe_period_s(float(np.linalg.norm(T.t_mm)))
    assert 1e-3 < period < 6e-3  # exposure + readout
    # the yaw rate (deg/s) over a sub-frame period shows up between the first and last
    dyaw = np.degrees(np.arccos(np.clip((np.trace(poses[3].R.T @ poses[0].R) - 1) / 2, -1, 1)))
    assert dyaw > 0.0
    off = _bench(motion_artefacts=False)
    off.turntable.move_to({"yaw": 10.0}, 0.0)
    assert off.subframe_poses(0.3, T) is None  # switched off: static renders throughout
