"""Simulator speed: median time to render one frame pair at default quality, one core.

Run: ``python bench/sim.py [--frames N]``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import med_p95, single_core, table  # noqa: E402
from tofpose import CameraModel  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import TargetScene  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=60)
    args = ap.parse_args()
    single_core()
    cam = CameraModel()
    rng = np.random.default_rng(0)
    rows = []
    for label, sensor in (
        ("default (4x4 edge supersampling)", SensorModel()),
        ("no supersampling", SensorModel(supersampling=1)),
        ("blur sigma 0.7 px", SensorModel(blur_sigma_px=0.7)),
    ):
        for z in (700.0, 3000.0, 10000.0):
            T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([0, -30, z]))
            render_frame(cam, TargetScene(), T, sensor, rng)
            times = []
            for _ in range(args.frames):
                t0 = time.perf_counter()
                render_frame(cam, TargetScene(), T, sensor, rng)
                times.append((time.perf_counter() - t0) * 1e3)
            m, p = med_p95(times)
            rows.append([label, f"{z / 1000:.1f} m", f"{m:.1f}", f"{p:.1f}", f"{1000 / m:.0f}"])
    # a slew: four phase sub-frames at their own poses (8 deg/s about the camera's y axis,
    # 2 ms apart, centred on the frame's stamp as ``SimulatedBench.subframe_poses`` takes
    # them), each a full ray cast, and the pose at the stamp for the truth's surface map
    T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([0, -30, 3000.0]))
    subs = [
        RigidTransform(
            rotation_from_euler_deg(0, 8.0 * 0.002 * (k - 1.5), 0) @ T.R,
            rotation_from_euler_deg(0, 8.0 * 0.002 * (k - 1.5), 0) @ T.t_mm,
        )
        for k in range(4)
    ]
    render_frame(cam, TargetScene(), T, SensorModel(), rng, subframe_poses=subs)
    times = []
    for _ in range(args.frames):
        t0 = time.perf_counter()
        render_frame(cam, TargetScene(), T, SensorModel(), rng, subframe_poses=subs)
        times.append((time.perf_counter() - t0) * 1e3)
    m, p = med_p95(times)
    rows.append(
        [
            "default, slewing 8 deg/s (4 sub-frames)",
            "3.0 m",
            f"{m:.1f}",
            f"{p:.1f}",
            f"{1000 / m:.0f}",
        ]
    )
    print(f"render one 320x240 frame pair, one core, {args.frames} frames")
    print(table(["sensor", "range", "median ms", "p95 ms", "frames/s"], rows))


if __name__ == "__main__":
    main()
