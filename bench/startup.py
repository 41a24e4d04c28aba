"""Start-up cost of the command line and the library, each in a fresh process (the way a
user meets it): ``tofpose --help``, ``import tofpose``, the pipeline's import (numba's
kernels from the warm cache) and its first frame. Medians over repeated runs; then which
heavy packages each start-up loaded (from ``sys.modules`` at its end).

Run: ``python bench/startup.py [--repeats N]``. Prints a Markdown table.
"""

from __future__ import annotations

import argparse
import json
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import table  # noqa: E402

#: packages whose import a start-up should not pay unless it needs them
HEAVY = ("numba", "cv2", "scipy", "fastapi", "sqlalchemy", "dask", "distributed", "h5py")

_REPORT = "import json, sys; print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"

#: (what, Python code run in a fresh interpreter)
CASES = (
    ("import tofpose", "import tofpose\n"),
    (
        "the parser (tofpose --help's work)",
        "from tofpose.cli import build_parser\nbuild_parser().format_help()\n",
    ),
    ("import tofpose.pipeline (kernels from the cache)", "import tofpose.pipeline\n"),
    (
        "the first pose (pipeline + one simulated frame)",
        "import numpy as np\n"
        "from tofpose import CameraModel, PosePipeline, paper_target\n"
        "from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg\n"
        "from tofpose.sim.bench import R_FACING\n"
        "from tofpose.sim.render import SensorModel, render_frame\n"
        "from tofpose.sim.scene import TargetScene\n"
        "cam = CameraModel()\n"
        "R = rotation_from_euler_deg(2, -3, 10) @ R_FACING\n"
        "T = RigidTransform(R, np.array([0.0, 0.0, 3000.0]))\n"
        "f = render_frame(cam, TargetScene(), T, SensorModel(), np.random.default_rng(0))\n"
        "assert PosePipeline(cam, paper_target()).process(f.gray, f.distance_mm).ok\n",
    ),
)


def time_run(argv: list[str]) -> tuple[float, list[str]]:
    """Wall time (s) of one process and the top-level packages it had loaded."""
    t0 = time.perf_counter()
    out = subprocess.run(argv, capture_output=True, text=True, check=True, timeout=900)
    elapsed = time.perf_counter() - t0
    last = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else "[]"
    return elapsed, json.loads(last) if last.startswith("[") else []


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    rows = []
    tofpose_exe = shutil.which("tofpose", path=str(Path(sys.executable).parent))
    if tofpose_exe:
        runs = [time_run([tofpose_exe, "--help"])[0] for _ in range(args.repeats)]
        rows.append(["`tofpose --help` (the installed command)", statistics.median(runs), "-"])
    for what, code in CASES:
        argv = [sys.executable, "-c", code + _REPORT]
        time_run(argv)  # one untimed run: the OS file cache, numba's index
        results = [time_run(argv) for _ in range(args.repeats)]
        loaded = sorted(set(results[0][1]) & set(HEAVY))
        rows.append([what, statistics.median(r[0] for r in results), ", ".join(loaded) or "none"])
    print(
        table(
            ["start-up", f"median s ({args.repeats} runs)", "heavy packages loaded"],
            [[w, f"{s:.2f}", h] for w, s, h in rows],
        )
    )


if __name__ == "__main__":
    main()
