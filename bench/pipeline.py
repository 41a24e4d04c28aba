"""Pipeline speed per stage on one core over simulated frames at several ranges.

Run: ``python bench/pipeline.py [--frames N]``. Prints a Markdown table of median and p95
milliseconds per stage and in total, per range, with the pose success rate.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import med_p95, single_core, table  # noqa: E402
from tofpose import CameraModel, PosePipeline, paper_target  # noqa: E402
from tofpose.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import TargetScene  # noqa: E402

STAGES = [
    "levels",
    "blobs",
    "ellipses",
    "centroids",
    "backproject",
    "matching",
    "refine",
    "total",
]
CASES = [
    (700.0, (-110.0, -55.0)),
    (1500.0, (0.0, -30.0)),
    (3000.0, (0.0, -30.0)),
    (5712.0, (2.0, -10.0)),
    (10000.0, (0.0, 0.0)),
]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    single_core()
    cam, cat = CameraModel(), paper_target()
    rows = []
    rng = np.random.default_rng(0)
    for z, off in CASES:
        R = rotation_from_euler_deg(2, -3, 10) @ R_FACING
        T = RigidTransform(R, np.array([*off, z]))
        frames = [
            render_frame(cam, TargetScene(), T, SensorModel(), rng) for _ in range(args.frames)
        ]
        per_stage: dict[str, list[float]] = {s: [] for s in STAGES}
        n_ok = 0
        for _ in range(args.repeats):
            pipe = PosePipeline(cam, cat)
            for f in frames:
                r = pipe.process(f.gray, f.distance_mm)
                n_ok += r.ok
                for s in STAGES:
                    per_stage[s].append(r.timings_ms.get(s, 0.0))
        cells = [f"{z / 1000:.1f} m", f"{n_ok / (args.frames * args.repeats):.0%}"]
        for s in STAGES:
            m, p = med_p95(per_stage[s])
            cells.append(f"{m:.2f} / {p:.2f}")
        rows.append(cells)
    print(
        f"pipeline time per frame, ms (median / p95), one core, "
        f"{args.frames} frames x {args.repeats}"
    )
    print(table(["range", "ok", *STAGES], rows))


if __name__ == "__main__":
    main()
