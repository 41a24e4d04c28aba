"""Issue 47's goals in one run: every row of its table ("what a user waits for") measured
on this machine beside a reference measured in the same run, as a ratio, with the goal
and whether the numbers meet it.

Rows (reference in brackets):

- first pose with ``ok`` true from ``tofpose serve``'s start, as ``make run`` starts it,
  with a fresh numba cache (``NUMBA_CACHE_DIR``: a fresh clone's state) [the same start
  with the kernels cached];
- ``tofpose --help`` [``python -c pass``: the interpreter's own start];
- ``import tofpose`` in a fresh process [``python -c pass``], and which of the web
  stack, Dask, numba and OpenCV it loaded; ``python -X importtime`` names its costliest
  packages;
- ``tofpose estimate --no-pixel-fit`` per frame of a range-sweep recording, and the
  default ``tofpose estimate`` (each pose refined on its pixels) on a tenth of it
  [OpenCV SimpleBlobDetector + solvePnP given the true correspondences on the same
  frames];
- acquisition and tracking per frame (``bench/pipeline.py``) [OpenCV as above]; Python
  calls and calls into compiled code per frame (cProfile);
- ``tofpose reprocess --no-pixel-fit`` on a LocalCluster of 1 and 2 workers, both modes,
  frames/s per worker [``tofpose estimate --no-pixel-fit`` serially], and chunks run
  more than once;
- a study on 1 worker, frames/s [the same frames serially in one process];
- ``tofpose study --example`` on 2 workers: the cluster's start [a bare Dask
  LocalCluster of 2 workers started in a fresh process] and the first progress update
  [one chunk of the example measured serially];
- server memory through a short day's use (``bench/memory.py``, one round) [the same
  server idle].

Each figure is the median over repeats (min-max beside it); the ratio is the median
measured over the median reference; "met" is computed from them. ``--quick``: tiny
workloads, one repeat (for trying it out and for the tests).

Run: ``python bench/goals.py [--quick] [--only first_pose startup ...]`` (``GROUPS``).
Prints the table (progress on stderr).
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench._common import all_cores, free_port, single_core, table  # noqa: E402

#: packages ``import tofpose`` should not load (issue 47, item 3)
HEAVY = ("fastapi", "starlette", "uvicorn", "sqlalchemy", "dask", "distributed", "numba", "cv2")
_LOADED = "import json, sys; print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))"


@dataclass
class Row:
    """One goal: ``measured`` and ``reference`` hold one value per repeat (same unit);
    ``kind`` says what the goal bounds: "measured <=", "ratio <=" or "ratio >=" with
    ``bound``, or "checks" (only ``checks`` decide). ``checks``: further conditions of
    the goal, by name, each True when met; ``note``: what the measured cell adds."""

    key: str
    what: str
    unit: str
    measured: list[float]
    reference_what: str
    reference: list[float]
    goal: str
    kind: str
    bound: float = float("nan")
    checks: dict[str, bool] = field(default_factory=dict)
    note: str = ""

    @property
    def measured_median(self) -> float:
        return float(np.median(self.measured))

    @property
    def reference_median(self) -> float:
        return float(np.median(self.reference)) if self.reference else float("nan")

    @property
    def ratio(self) -> float:
        """Median measured / median reference (NaN without a reference)."""
        return self.measured_median / self.reference_median if self.reference else float("nan")

    @property
    def met(self) -> bool:
        ok = all(self.checks.values())
        if self.kind == "measured <=":
            return ok and self.measured_median <= self.bound
        if self.kind == "ratio <=":
            return ok and self.ratio <= self.bound
        if self.kind == "ratio >=":
            return ok and self.ratio >= self.bound
        if self.kind == "checks":
            return ok and bool(self.checks)
        raise ValueError(f"row {self.key}: unknown goal kind {self.kind!r}")


def _spread(values: list[float], unit: str, digits: int) -> str:
    med = float(np.median(values))
    text = f"{med:.{digits}f} {unit}".rstrip()
    if len(values) > 1:
        text += f" ({min(values):.{digits}f}-{max(values):.{digits}f})"
    return text


def _digits(values: list[float]) -> int:
    m = abs(float(np.median(values))) if values else 0.0
    return 0 if m >= 100 else 1 if m >= 10 else 2 if m >= 0.1 else 3


HEADER = [
    "what a user waits for",
    "measured, median (min-max)",
    "reference in the same run",
    "ratio",
    "goal",
    "met?",
]


def markdown(rows: list[Row]) -> str:
    """The goals table (``HEADER``), one line per row."""
    body = []
    for r in rows:
        measured = _spread(r.measured, r.unit, _digits(r.measured))
        if r.note:
            measured += f"; {r.note}"
        ref = (
            f"{r.reference_what}: {_spread(r.reference, r.unit, _digits(r.reference))}"
            if r.reference
            else "-"
        )
        ratio = f"{r.ratio:.2f}x" if r.reference else "-"
        body.append([r.what, measured, ref, ratio, r.goal, "yes" if r.met else "no"])
    return table(HEADER, body)


# -- the measurements ------------------------------------------------------------------


def _env() -> dict[str, str]:
    """This checkout's code in every child process."""
    path = os.environ.get("PYTHONPATH")
    return {**os.environ, "PYTHONPATH": str(ROOT) + (os.pathsep + path if path else "")}


def _wall_s(argv: list[str], env: dict[str, str] | None = None) -> tuple[float, str]:
    """(wall s, stdout) of one process run to its end."""
    t0 = time.perf_counter()
    out = subprocess.run(
        argv, capture_output=True, text=True, check=True, timeout=600, env=env or _env(), cwd=ROOT
    )
    return time.perf_counter() - t0, out.stdout


def first_pose_s(numba_cache_dir: str | None, timeout_s: float = 600.0) -> tuple[float, str]:
    """Seconds from starting ``tofpose serve`` (simulated devices, viser on, as ``make
    run`` starts it; a temporary data directory) to its first pose with ``ok`` true,
    and which implementation of the pipeline ran then (``/api/health``).
    ``numba_cache_dir``: where numba's cache is (an empty directory: nothing compiled
    yet), None for this checkout's."""
    import httpx

    env = _env()
    if numba_cache_dir is not None:
        env["NUMBA_CACHE_DIR"] = numba_cache_dir
    with tempfile.TemporaryDirectory(prefix="tofpose-goals-") as d:
        port = free_port()
        argv = [sys.executable, "-m", "tofpose.cli", "serve", "--port", str(port)]
        argv += ["--data-dir", d, "--viser-port", str(free_port())]
        t0 = time.perf_counter()
        proc = subprocess.Popen(
            argv, env=env, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL
        )
        try:
            with httpx.Client(base_url=f"http://127.0.0.1:{port}", timeout=2.0) as http:
                while time.perf_counter() - t0 < timeout_s:
                    if proc.poll() is not None:
                        raise RuntimeError(f"tofpose serve exited ({proc.returncode})")
                    try:
                        pose = http.get("/api/pose/latest")
                        if pose.status_code == 200 and pose.json().get("ok"):
                            seconds = time.perf_counter() - t0
                            implementation = http.get("/api/health").json()["pipeline"]
                            return seconds, str(implementation.get("implementation"))
                    except (httpx.HTTPError, ValueError):
                        pass
                    time.sleep(0.1)
            raise RuntimeError(f"no ok pose within {timeout_s:g} s")
        finally:
            proc.terminate()
            try:
                proc.wait(60)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def first_pose_row(repeats: int, progress: Callable[[str], None]) -> Row:
    fresh, warm, by = [], [], set()
    for k in range(repeats):
        with tempfile.TemporaryDirectory(prefix="tofpose-numba-") as cache:
            progress(f"first pose, fresh numba cache ({k + 1}/{repeats})")
            s, impl = first_pose_s(cache)
        fresh.append(s)
        by.add(impl)
        progress(f"first pose, kernels cached ({k + 1}/{repeats})")
        warm.append(first_pose_s(None)[0])
    return Row(
        "first_pose",
        "`tofpose serve` (as `make run` starts it) -> first pose with `ok` true, fresh numba cache",
        "s",
        fresh,
        "kernels cached",
        warm,
        "<= 30 s",
        "measured <=",
        30.0,
        note=f"pose from the {', '.join(sorted(by))} implementation",
    )


def _tofpose_exe() -> list[str]:
    exe = shutil.which("tofpose", path=str(Path(sys.executable).parent))
    return [exe] if exe else [sys.executable, "-m", "tofpose.cli"]


def startup_rows(repeats: int, progress: Callable[[str], None]) -> list[Row]:
    """``tofpose --help`` and ``import tofpose``, each against ``python -c pass``."""
    progress("tofpose --help, import tofpose, python -c pass")
    bare = [sys.executable, "-c", "pass"]
    help_argv = [*_tofpose_exe(), "--help"]
    imp = [sys.executable, "-c", "import tofpose\n" + _LOADED]
    for argv in (bare, help_argv, imp):
        _wall_s(argv)  # untimed: the OS file cache
    ref, helps, imports, loaded = [], [], [], set()
    for _ in range(repeats):  # interleaved: a slow spell of the machine is shared
        ref.append(_wall_s(bare)[0])
        helps.append(_wall_s(help_argv)[0])
        s, out = _wall_s(imp)
        imports.append(s)
        loaded |= set(json.loads(out.strip().splitlines()[-1])) & set(HEAVY)
    return [
        Row(
            "help",
            "`tofpose --help`",
            "s",
            helps,
            "`python -c pass`",
            ref,
            "<= 0.5 s",
            "measured <=",
            0.5,
        ),
        Row(
            "import",
            "`import tofpose` in a fresh process",
            "s",
            imports,
            "`python -c pass`",
            ref,
            "loads none of " + ", ".join(HEAVY),
            "checks",
            checks={"no heavy package": not loaded},
            note="loaded " + (", ".join(sorted(loaded)) or "none of them"),
        ),
    ]


def _import_ms(code: str) -> dict[str, float]:
    """ms each top-level package's modules took to import themselves (``python -X
    importtime -c CODE``, self times summed by package)."""
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", code],
        capture_output=True,
        text=True,
        check=True,
        env=_env(),
        cwd=ROOT,
    )
    sums: dict[str, float] = {}
    for line in out.stderr.splitlines():
        if not line.startswith("import time:") or "[us]" in line:
            continue
        self_us, _, name = (c.strip() for c in line[len("import time:") :].split("|"))
        pkg = name.split(".")[0]
        sums[pkg] = sums.get(pkg, 0.0) + int(self_us) / 1e3
    return sums


def import_offenders(repeats: int, top: int = 8) -> list[tuple[str, float]]:
    """The top-level packages ``import tofpose`` spends most in, by their modules' own
    import time, ms, median over repeats; those the bare interpreter imports too
    (``site``, ``encodings``, ...) left out."""
    bare = set(_import_ms("pass"))
    per: dict[str, list[float]] = {}
    for _ in range(repeats):
        for pkg, ms in _import_ms("import tofpose").items():
            per.setdefault(pkg, []).append(ms)
    med = {
        p: float(np.median(v + [0.0] * (repeats - len(v)))) for p, v in per.items() if p not in bare
    }
    return sorted(med.items(), key=lambda kv: -kv[1])[:top]


def _recording(n_frames: int) -> Path:
    """The deterministic range-sweep recording ``bench/scaleout.py`` makes (seed 4),
    kept in the temporary directory between runs."""
    from bench.scaleout import make_recording

    rec = Path(tempfile.gettempdir()) / f"tofpose-bench-sweep-{n_frames}.h5"
    if not rec.exists():
        make_recording(rec, n_frames)
    return rec


def opencv_ms_per_frame(rec_path: Path) -> float:
    """OpenCV SimpleBlobDetector + solvePnP (SQPnP) on every frame of a recording with
    truth, the correspondences given (``bench.baseline.baseline_pose``; the recording's
    reading not timed): mean ms per frame."""
    from bench.baseline import baseline_pose, blob_detector
    from tofpose import paper_target
    from tofpose.core.geometry import RigidTransform
    from tofpose.io.recording import open_recording

    det, cat = blob_detector(), paper_target()
    total = 0.0
    with open_recording(rec_path) as rec:
        assert rec.truth_R is not None and rec.truth_t_mm is not None
        for i in range(rec.n_frames):
            gray, _, _ = rec.frame(i)
            T = RigidTransform(rec.truth_R[i], rec.truth_t_mm[i])
            total += baseline_pose(gray, rec.camera, cat, T, det, ransac=False)[2]
        return total / rec.n_frames


def read_ms_per_frame(rec_path: Path) -> float:
    """Reading a recording's frames as ``tofpose estimate`` reads them (blocks aligned
    to its HDF5 chunks), mean ms per frame."""
    from tofpose.io.recording import open_recording

    t0 = time.perf_counter()
    with open_recording(rec_path) as rec:
        for _ in rec.blocks():
            pass
        return 1e3 * (time.perf_counter() - t0) / rec.n_frames


def reading_setup(rec_path: Path) -> str:
    """How ``tofpose estimate`` reads the recording here: its images' HDF5 filters and
    whether ``Recording.blocks`` reads ahead in a thread (it does when this process may
    use more than one core)."""
    import h5py

    from tofpose.io.recording import open_recording

    with h5py.File(rec_path, "r") as f:
        ds = f["frames/distance_mm"]
        filters = f"{ds.compression} {ds.compression_opts}" if ds.compression else "none"
        filters += " + shuffle" if ds.shuffle else ""
    with open_recording(rec_path) as rec:
        blocks = rec.blocks()
        next(blocks)
        ahead = rec.reading_ahead
        blocks.close()
    return f"{filters}; {'a reader thread' if ahead else 'no reader thread'}"


def estimate_row(
    n_frames: int, repeats: int, progress: Callable[[str], None], pixel_fit: bool = False
) -> Row:
    """``tofpose estimate`` (acquisition mode, in this process: the command's work without
    its start, the range bias's learning pass included) per frame against OpenCV on the
    same frames; one core. ``pixel_fit``: as the command runs by default (each pose
    refined on its pixels), else ``--no-pixel-fit``."""
    from tofpose.workflows.measurement import estimate

    flag = "" if pixel_fit else " --no-pixel-fit"
    progress(f"estimate{flag} vs OpenCV, {n_frames}-frame recording")
    rec = _recording(n_frames)
    ours, theirs, reading = [], [], []
    with tempfile.TemporaryDirectory() as d:
        out = str(Path(d) / "e.csv")
        estimate(str(rec), out, None, None, progress=False, pixel_fit=pixel_fit)  # warm
        for _ in range(repeats):
            t0 = time.perf_counter()
            s = estimate(str(rec), out, None, None, progress=False, pixel_fit=pixel_fit)
            ours.append(1e3 * (time.perf_counter() - t0) / s["frames"])
            theirs.append(opencv_ms_per_frame(rec))
            reading.append(read_ms_per_frame(rec))
    what = "the default: each pose refined on its pixels" if pixel_fit else "centroid pose only"
    return Row(
        "estimate" if not pixel_fit else "estimate_pixel_fit",
        f"`tofpose estimate{flag}` per frame ({what}; read, measure, write the CSV; one core)",
        "ms",
        ours,
        "SimpleBlobDetector + solvePnP, true correspondences, same frames",
        theirs,
        "<= 1.0x",
        "ratio <=",
        1.0,
        note=f"of which reading the recording {np.median(reading):.2f} ms ({reading_setup(rec)})",
    )


def _is_compiled(key: tuple[str, int, str]) -> bool:
    """Whether a cProfile entry is compiled code: a numba kernel (its dispatcher reports
    the call under the kernel's file) or an OpenCV / SciPy C function."""
    filename, _, name = key
    if "/kernels/" in filename:
        return True
    return filename == "~" and any(m in name for m in ("cv2.", "scipy", "_ckdtree"))


def call_counts(frames, config, mode: str) -> tuple[float, float]:
    """(Python-level calls, calls into compiled code) per frame the pipeline measured in
    ``mode`` (cProfile, median over the frames)."""
    from tofpose import CameraModel, PosePipeline, paper_target

    pipe = PosePipeline(CameraModel(), paper_target(), config)
    calls, compiled = [], []
    for f in frames:
        prof = cProfile.Profile()
        prof.enable()
        r = pipe.process(f.gray, f.distance_mm)
        prof.disable()
        if r.mode != mode:
            continue
        stats = pstats.Stats(prof).stats  # type: ignore[attr-defined]
        calls.append(sum(v[1] for v in stats.values()))
        compiled.append(sum(v[1] for k, v in stats.items() if _is_compiled(k)))
    return float(np.median(calls)), float(np.median(compiled))


def pipeline_rows(n_frames: int, repeats: int, progress: Callable[[str], None]) -> list[Row]:
    """Acquisition and tracking per frame against OpenCV (``bench.pipeline.run``: every
    range of its table, one core; each repeat's median over all ranges' frames), and
    their calls per frame."""
    from bench import pipeline
    from tofpose import CameraModel
    from tofpose.core.geometry import RigidTransform, rotation_from_euler_deg
    from tofpose.sim.bench import R_FACING
    from tofpose.sim.render import SensorModel, render_frame
    from tofpose.sim.scene import TargetScene

    acq, trk, cv = [], [], []
    for k in range(repeats):
        progress(f"acquisition and tracking vs OpenCV ({k + 1}/{repeats})")
        rows = pipeline.run(n_frames, 1)
        acq.append(float(np.median([x for r in rows for x in r["stages"]["total"]])))
        trk.append(float(np.median([x for r in rows for x in r["tracking"]])))
        cv.append(float(np.median([x for r in rows for x in r["opencv"]])))
    progress("calls per frame (cProfile)")
    cam, rng = CameraModel(), np.random.default_rng(1)
    frames = []
    for z, off in pipeline.CASES:
        T = RigidTransform(rotation_from_euler_deg(2, -3, 10) @ R_FACING, np.array([*off, z]))
        frames += [render_frame(cam, TargetScene(), T, SensorModel(), rng) for _ in range(4)]
    from tofpose import PipelineConfig

    counts = {
        "acquisition": call_counts(frames, PipelineConfig(), "acquisition"),
        "tracking": call_counts(frames, pipeline.TRACKING, "tracking"),
    }
    out = [
        Row(
            "acquisition",
            "acquisition per frame (`bench/pipeline.py`, all ranges, one core)",
            "ms",
            acq,
            "OpenCV, same frames",
            cv,
            "<= 1.5x",
            "ratio <=",
            1.5,
        ),
        Row(
            "tracking",
            "tracking per frame (`bench/pipeline.py`, all ranges, one core)",
            "ms",
            trk,
            "OpenCV, same frames",
            cv,
            "<= 0.7x",
            "ratio <=",
            0.7,
        ),
    ]
    for mode, (calls, compiled) in counts.items():
        out.append(
            Row(
                f"{mode}_calls",
                f"{mode}: Python calls per frame (cProfile)",
                "",
                [calls],
                "",
                [],
                "one compiled call a frame",
                "checks",
                checks={"one compiled call": compiled <= 1},
                note=f"{compiled:.0f} of them into compiled code",
            )
        )
    return out


def _serial_on_cores(rec: Path, tracking: bool, cores: int) -> float:
    """``tofpose estimate`` frames/s in this process pinned to ``cores`` of its cores (one
    core: no reader thread, as a worker that shares the cores)."""
    import cv2

    from bench.scaleout import serial_estimate

    mine = sorted(os.sched_getaffinity(0))
    cv_threads = cv2.getNumThreads()
    # Linux pins the calling thread (threads it starts inherit it; OpenCV's pool, started
    # before, does not: it is held to one thread instead)
    os.sched_setaffinity(0, mine[: max(1, cores)])
    cv2.setNumThreads(max(1, cores))
    try:
        return serial_estimate(rec, tracking)[0]
    finally:
        os.sched_setaffinity(0, mine)
        cv2.setNumThreads(cv_threads)


def reprocess_rows(
    n_frames: int, repeats: int, chunk_frames: int, progress: Callable[[str], None]
) -> list[Row]:
    """``tofpose reprocess`` on 1 and 2 workers, both modes, frames/s per worker against
    ``tofpose estimate`` serially on a worker's share of the cores (``bench.scaleout``):
    a worker of w on c cores has c // w of them (at least one), and the serial run in
    the same run is pinned to as many, so the ratio is the workers' parallel
    efficiency, not the count of cores."""
    from bench.scaleout import reprocess_run
    from tofpose.warmup import warm_up

    rec = _recording(n_frames)
    warm_up()  # the serial runs with the kernels loaded, as the workers' "once up" rate
    cores = len(os.sched_getaffinity(0))
    share = {w: max(1, cores // w) for w in (1, 2)}
    out = []
    for tracking in (False, True):
        mode = "--tracking" if tracking else "acquisition"
        serial: dict[int, list[float]] = {c: [] for c in set(share.values())}
        per_worker: dict[int, list[float]] = {1: [], 2: []}
        twice = dict.fromkeys(per_worker, 0)
        ahead = dict.fromkeys(per_worker, False)
        for k in range(repeats):
            progress(f"reprocess {mode}: serial, 1 and 2 workers ({k + 1}/{repeats})")
            for c in serial:
                serial[c].append(_serial_on_cores(rec, tracking, c))
            for w in per_worker:
                r = reprocess_run(rec, w, tracking, chunk_frames)
                per_worker[w].append(r["fps"] / w)
                twice[w] += r["twice"]
                ahead[w] = r["read_ahead"]
        for w, fps in per_worker.items():
            c = share[w]
            out.append(
                Row(
                    f"reprocess_{'tracking' if tracking else 'acquisition'}_{w}",
                    f"`tofpose reprocess --no-pixel-fit` {mode}, {n_frames} frames, {w} worker"
                    + ("s" if w > 1 else "")
                    + ", frames/s per worker",
                    "frames/s",
                    fps,
                    f"`tofpose estimate --no-pixel-fit` serially on {c} core"
                    + ("s" if c > 1 else ""),
                    serial[c],
                    ">= 0.9x; no chunk run twice",
                    "ratio >=",
                    0.9,
                    checks={"no chunk run twice": twice[w] == 0},
                    note=f"chunks run again: {twice[w]}; "
                    + ("a reader thread per worker" if ahead[w] else "no reader thread"),
                )
            )
    return out


def study_row(frames_per_cell: int, repeats: int, progress: Callable[[str], None]) -> Row:
    """A study on 1 worker against the same frames serially (``bench.scaleout``)."""
    from bench.scaleout import serial_study, study_run, study_spec

    spec = study_spec(frames_per_cell)
    serial, one = [], []
    for k in range(repeats):
        progress(f"study: serial and 1 worker ({k + 1}/{repeats})")
        serial.append(serial_study(spec)[0])
        one.append(study_run(spec, 1)["fps"])
    return Row(
        "study",
        f"study ({spec.n_frames} frames), 1 worker, frames/s",
        "frames/s",
        one,
        "the same frames serially",
        serial,
        ">= 0.9x",
        "ratio >=",
        0.9,
    )


_BARE_CLUSTER = (
    "import time\n"
    "from dask.distributed import Client, LocalCluster\n"
    "t0 = time.perf_counter()\n"
    "cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True,"
    " dashboard_address=None)\n"
    "client = Client(cluster)\n"
    "print(time.perf_counter() - t0)\n"
    "client.close()\n"
    "cluster.close()\n"
)


def example_chunk_serial_s() -> float:
    """Seconds to measure the first chunk of ``tofpose study --example`` in this process
    (kernels loaded before)."""
    from tofpose.core.camera import CameraModel
    from tofpose.study.frames import measure_frame
    from tofpose.study.spec import EXAMPLE, StudySpec

    spec = StudySpec.from_dict(EXAMPLE)
    cam, cell = CameraModel(), spec.cells[0]
    measure_frame(spec, cell, 0, cam)  # the kernels and the cell's pipeline
    t0 = time.perf_counter()
    for i in range(spec.chunk_frames):
        measure_frame(spec, cell, i, cam)
    return time.perf_counter() - t0


def example_rows(repeats: int, progress: Callable[[str], None]) -> list[Row]:
    """``tofpose study --example`` on 2 workers from the command line (``bench.scaleout.
    study_example_cli``): its cluster start against a bare Dask LocalCluster's, its first
    progress against one chunk measured serially."""
    from bench.scaleout import study_example_cli

    starts, firsts, bare, chunk = [], [], [], []
    for k in range(repeats):
        progress(f"study --example on 2 workers, bare LocalCluster ({k + 1}/{repeats})")
        r = study_example_cli(2)
        starts.append(r["start_s"])
        firsts.append(r["first"])
        bare.append(float(_wall_s([sys.executable, "-c", _BARE_CLUSTER])[1].split()[-1]))
        chunk.append(example_chunk_serial_s())
    return [
        Row(
            "example_start",
            "`tofpose study --example`, 2 workers: cluster start",
            "s",
            starts,
            "bare Dask LocalCluster, 2 workers",
            bare,
            "<= 3 s",
            "measured <=",
            3.0,
        ),
        Row(
            "example_progress",
            "`tofpose study --example`, 2 workers: first progress, from its start",
            "s",
            firsts,
            "one chunk measured serially",
            chunk,
            "<= 5 s",
            "measured <=",
            5.0,
        ),
    ]


def memory_row(ws_seconds: float, progress: Callable[[str], None]) -> Row:
    """The server's largest RSS over one round of ``bench/memory.py`` (campaign, reports,
    MCAP export, refused and accepted study, 50 clients) against its RSS idle, MB."""
    from bench.memory import one_repeat

    progress("server memory, one round of bench/memory.py")
    steps = one_repeat(1, ws_seconds)
    mb = [rss * 2**20 / 1e6 for _, rss, _ in steps]
    return Row(
        "memory",
        "server memory (RSS) through one round: campaign, reports, MCAP, studies, 50 clients",
        "MB",
        [max(mb)],
        "the same server idle",
        [mb[0]],
        "<= 700 MB",
        "measured <=",
        700.0,
        note=f"largest after {steps[int(np.argmax(mb))][0]}",
    )


#: the rows' groups in the order they run; ``--only`` names some of them
GROUPS = (
    "first_pose",
    "startup",
    "estimate",
    "pipeline",
    "reprocess",
    "study",
    "example",
    "memory",
)


def run(
    quick: bool, only: tuple[str, ...] = GROUPS, progress: Callable[[str], None] | None = None
) -> tuple[list[Row], list[tuple[str, float]]]:
    """The rows of ``only`` (``GROUPS``) and the costliest imports of ``import tofpose``
    (when "startup" runs). ``quick``: tiny workloads, one repeat (a few repeats of the
    process starts)."""
    unknown = set(only) - set(GROUPS)
    if unknown:
        raise ValueError(f"unknown goal groups {sorted(unknown)}; known: {', '.join(GROUPS)}")
    from tqdm import tqdm

    bar = tqdm(total=len(only), desc="goals", unit="group", file=sys.stderr)

    def say(what: str) -> None:
        bar.set_postfix_str(what)
        if progress is not None:
            progress(what)

    reps = 1 if quick else 3
    rows: list[Row] = []
    offenders: list[tuple[str, float]] = []
    for group in (g for g in GROUPS if g in only):
        if group == "first_pose":
            rows.append(first_pose_row(1 if quick else 2, say))
        elif group == "startup":
            rows += startup_rows(3 if quick else 5, say)
            offenders = import_offenders(1 if quick else 3)
        elif group in ("estimate", "pipeline"):
            single_core()
            try:
                if group == "estimate":
                    rows.append(estimate_row(200 if quick else 3000, reps, say))
                    # the default's pixel fit on a tenth of the frames (tens of ms each)
                    rows.append(estimate_row(20 if quick else 300, reps, say, pixel_fit=True))
                else:
                    rows += pipeline_rows(4 if quick else 20, reps, say)
            finally:
                all_cores()
        elif group == "reprocess":
            rows += reprocess_rows(
                200 if quick else 3000, 1 if quick else 2, 100 if quick else 500, say
            )
        elif group == "study":
            rows.append(study_row(4 if quick else 48, 1 if quick else 2, say))
        elif group == "example":
            rows += example_rows(1 if quick else 2, say)
        elif group == "memory":
            rows.append(memory_row(2.0 if quick else 10.0, say))
        bar.update()
    bar.close()
    return rows, offenders


def offenders_text(offenders: list[tuple[str, float]]) -> str:
    return (
        '`python -X importtime -c "import tofpose"`, the costliest packages (their '
        "modules' own import time, ms, median; those `python -c pass` imports too left out): "
        + ", ".join(f"{p} {ms:.1f}" for p, ms in offenders)
        + "."
    )


def report(rows: list[Row], offenders: list[tuple[str, float]], load: tuple[float, float]) -> str:
    """The table and what it rests on, as Markdown."""
    lines = [markdown(rows), ""]
    if offenders:
        lines += [offenders_text(offenders), ""]
    met = sum(r.met for r in rows)
    lines.append(
        f"{met} of {len(rows)} goals met. Load average {load[0]:.1f} at the start, "
        f"{load[1]:.1f} at the end (2 cores shared with other work): the ratios count, "
        "the absolute times move with the load."
    )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny workloads, one repeat")
    ap.add_argument("--only", nargs="+", choices=GROUPS, default=list(GROUPS))
    args = ap.parse_args()
    all_cores()
    before = os.getloadavg()[0]
    rows, offenders = run(args.quick, tuple(args.only))
    print(report(rows, offenders, (before, os.getloadavg()[0])))


if __name__ == "__main__":
    main()
