"""Pipeline speed on one core over simulated streams at several ranges: acquisition (the
full pass on every frame) and tracking (``PipelineConfig.tracking``: windows around the
predicted reflectors, a full pass every 15 frames and whenever tracking fails), Python
function calls per frame, and OpenCV's SimpleBlobDetector + solvePnP (SQPnP) timed in the
same run on the same frames, so the ratio is measured side by side. The baseline gets its
correspondences for free (``bench.baseline.strict_correspondences``, not timed).

Run: ``python bench/pipeline.py [--frames N] [--repeats R]``. Prints two Markdown tables:
totals per mode with the ratio to OpenCV, and acquisition per stage (median / p95).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import med_p95, single_core, table  # noqa: E402
from bench.baseline import baseline_pose, blob_detector  # noqa: E402
from tofpose import CameraModel, PipelineConfig, PosePipeline, paper_target  # noqa: E402
from tofpose.calibration.range import RangeCorrection  # noqa: E402
from tofpose.config import TrackingConfig  # noqa: E402
from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg  # noqa: E402
from tofpose.sim.bench import R_FACING  # noqa: E402
from tofpose.sim.render import SensorModel, render_frame  # noqa: E402
from tofpose.sim.scene import TargetScene  # noqa: E402
from tofpose.warmup import warm_up  # noqa: E402

STAGES = ["levels", "blobs", "ellipses", "measurement", "matching", "refine", "total"]
CASES = [
    (700.0, (-110.0, -55.0)),
    (1500.0, (0.0, -30.0)),
    (3000.0, (0.0, -30.0)),
    (5712.0, (2.0, -10.0)),
    (10000.0, (0.0, 0.0)),
]
TRACKING = PipelineConfig(tracking=TrackingConfig(enabled=True))
#: a calibrated camera's range correction with every term of the model, sub-millimetre
#: here so that the ideal sensor's frames still fit (larger terms on frames without the
#: errors they remove fail tracking's consistency check at 0.7 m); a correction's values
#: do not change the work per frame, and a fitted one is in ``bench/realistic.py``
CORRECTION = RangeCorrection(
    SensorModel().unambiguous_range_mm,
    offset_mm=0.3,
    harmonics_mm=((0.2, -0.15), (0.05, 0.03)),
    amplitude_mm_per_decade=0.1,
    pixel_offsets_mm=np.random.default_rng(7).normal(0.0, 0.2, CameraModel().shape),
)


def call_profile(pipe: PosePipeline, frames, mode: str) -> tuple[list[int], list[float]]:
    """For each frame the pipeline measured in ``mode``: the Python-level function calls
    (and C functions called from Python), and the ms spent inside compiled code: the
    kernels (``tofpose/kernels``, whose numba dispatchers report their calls to a
    profiler) and OpenCV's and SciPy's C functions. The rest of a frame's time is Python
    and NumPy glue. A profiled pass (not the timed one): the profiler slows the Python,
    and adds about a microsecond to each compiled call it brackets (so the compiled share
    is an upper bound); ``run`` repeats it with the timed passes, so that a slow spell of
    the machine does not land on one range's profile."""
    count = 0
    inside = 0.0
    started: list = []  # (frame or C function, start time) of the compiled call running

    def prof(frame, event, arg):
        nonlocal count, inside
        if event in ("call", "c_call"):
            count += 1
        if started:
            key, t0 = started[-1]
            if (event == "return" and frame is key) or (
                event in ("c_return", "c_exception") and arg is key
            ):
                inside += time.perf_counter() - t0
                started.pop()
            return
        if event == "call" and "/kernels/" in frame.f_code.co_filename:
            started.append((frame, time.perf_counter()))
        elif event == "c_call" and str(getattr(arg, "__module__", "")).startswith(("cv2", "scipy")):
            started.append((arg, time.perf_counter()))

    calls, ms = [], []
    for f in frames:
        count, inside = 0, 0.0
        sys.setprofile(prof)
        try:
            r = pipe.process(f.gray, f.distance_mm)
        finally:
            sys.setprofile(None)
        if r.mode == mode:
            calls.append(count)
            ms.append(1e3 * inside)
    return calls, ms


def run(n_frames: int, repeats: int):
    """Time every range once per repeat, the ranges inside the repeats: this machine has
    slow phases of a minute or so, and timing one range after another put a whole
    phase on one range (its row, not the pipeline, looked slow)."""
    single_core()
    warm_up()  # compiled kernels loaded before timing, as the server does at start
    cam, cat = CameraModel(), paper_target()
    det = blob_detector()
    rng = np.random.default_rng(0)
    streams = []
    for z, off in CASES:
        T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([*off, z]))
        frames = [render_frame(cam, TargetScene(), T, SensorModel(), rng) for _ in range(n_frames)]
        streams.append((z, T, frames))
    rows = [
        {
            "range": z,
            "acq_ok": [],
            "stages": {s: [] for s in STAGES},
            "tracking": [],
            "tracking_corrected": [],
            "tracking_all": [],
            "opencv": [],
            "profile": {"acquisition": ([], []), "tracking": ([], [])},
        }
        for z, _, _ in streams
    ]
    for _ in range(repeats):
        for row, (_, T, frames) in zip(rows, streams, strict=True):
            pipe = PosePipeline(cam, cat)
            for f in frames:
                r = pipe.process(f.gray, f.distance_mm)
                row["acq_ok"].append(r.ok)
                for s in STAGES:
                    row["stages"][s].append(r.timings_ms.get(s, 0.0))
            pipe = PosePipeline(cam, cat, TRACKING)
            for f in frames:
                t0 = time.perf_counter()
                r = pipe.process(f.gray, f.distance_mm)
                ms = 1e3 * (time.perf_counter() - t0)
                row["tracking_all"].append(ms)
                if r.mode == "tracking":
                    row["tracking"].append(ms)
            pipe = PosePipeline(cam, cat, TRACKING, range_correction=CORRECTION)
            for f in frames:
                t0 = time.perf_counter()
                r = pipe.process(f.gray, f.distance_mm)
                if r.mode == "tracking":
                    row["tracking_corrected"].append(1e3 * (time.perf_counter() - t0))
            for f in frames:
                row["opencv"].append(baseline_pose(f.gray, cam, cat, T, det, ransac=False)[2])
            for mode, config in (("acquisition", PipelineConfig()), ("tracking", TRACKING)):
                calls, ms = call_profile(PosePipeline(cam, cat, config), frames, mode)
                row["profile"][mode][0].extend(calls)
                row["profile"][mode][1].extend(ms)
    for row in rows:
        row["ok"] = float(np.mean(row.pop("acq_ok")))
        row["tracked"] = len(row["tracking"]) / len(row["tracking_all"])
        profile = row.pop("profile")
        row["calls"] = tuple(float(np.median(profile[m][0])) for m in ("acquisition", "tracking"))
        row["compiled"] = tuple(
            float(np.median(profile[m][1])) for m in ("acquisition", "tracking")
        )
    return rows


def totals_table(rows) -> str:
    body = []
    for r in rows:
        acq = med_p95(r["stages"]["total"])
        trk = med_p95(r["tracking"]) if r["tracking"] else (np.nan, np.nan)
        corr = med_p95(r["tracking_corrected"]) if r["tracking_corrected"] else (np.nan, np.nan)
        cv = float(np.median(r["opencv"]))
        body.append(
            [
                f"{r['range'] / 1000:.1f} m",
                f"{r['ok']:.0%}",
                f"{acq[0]:.2f} / {acq[1]:.2f}",
                f"{trk[0]:.2f} / {trk[1]:.2f}",
                f"{corr[0]:.2f} / {corr[1]:.2f}",
                f"{r['tracked']:.0%}",
                f"{np.median(r['tracking_all']):.2f}",
                f"{r['calls'][0]:.0f} / {r['calls'][1]:.0f}",
                f"{r['compiled'][0]:.2f} / {r['compiled'][1]:.2f}",
                f"{cv:.2f}",
                f"{acq[0] / cv:.1f}",
                f"{trk[0] / cv:.1f}",
            ]
        )
    return table(
        [
            "range",
            "ok",
            "acquisition ms",
            "tracking ms",
            "tracking ms, range-corrected",
            "frames tracked",
            "stream ms (both)",
            "Python calls / frame (acq / track)",
            "ms in compiled code (acq / track)",
            "OpenCV ms",
            "acquisition / OpenCV",
            "tracking / OpenCV",
        ],
        body,
    )


def stages_table(rows) -> str:
    body = []
    for r in rows:
        cells = [f"{r['range'] / 1000:.1f} m", f"{r['ok']:.0%}"]
        for s in STAGES:
            m, p = med_p95(r["stages"][s])
            cells.append(f"{m:.2f} / {p:.2f}")
        body.append(cells)
    return table(["range", "ok", *STAGES], body)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--frames", type=int, default=60)
    ap.add_argument("--repeats", type=int, default=6)
    args = ap.parse_args()
    rows = run(args.frames, args.repeats)
    print(
        f"ms per frame (median / p95), one core, {args.frames} frames x {args.repeats} per "
        "range, every range timed once per repeat (a slow spell of the machine is shared "
        "by all ranges); tracking: the frames the tracking pipeline measured in tracking mode; "
        "range-corrected: the tracking pipeline of a camera with a calibrated range "
        "correction (every term of the model); "
        "stream: every frame of the tracking pipeline (acquisitions included); OpenCV: "
        "SimpleBlobDetector + solvePnP on the same frames, correspondences free; compiled "
        "code: time inside the kernels and OpenCV's and SciPy's C functions, median over "
        "profiled passes, one per repeat (the rest of a frame is Python and NumPy)"
    )
    print(totals_table(rows))
    print()
    print("acquisition per stage, ms (median / p95):")
    print(stages_table(rows))


if __name__ == "__main__":
    main()
