"""One chunk of a study: simulate its frames, measure them, judge them against truth,
write them to the store. This is the task a Dask worker runs (``run_chunk``).

Frame ``i`` of cell ``c`` draws its physics, pose and sensor noise from
``SeedSequence(seed, spawn_key=(c, i))`` (what ``SeedSequence(seed).spawn`` hands its
children), and the pipeline forgets every frame before it (a fresh acquisition), so the
rows depend on the spec alone. Per-frame columns: ``COLUMNS``.
"""

from __future__ import annotations

import math
import os
import sys
import time

import numpy as np
import pyarrow as pa

from tofpose.batch.worker import ProgressReporter
from tofpose.core.camera import CameraModel
from tofpose.core.catalog import BUILTIN_CATALOGS
from tofpose.core.geometry import quaternion_wxyz_from_rotation
from tofpose.core.threads import single_threaded_blas
from tofpose.lab.pose_judgement import judge, mahalanobis2, pose_error
from tofpose.pipeline import PosePipeline
from tofpose.sim.randomise import draw_background, draw_physics, draw_pose
from tofpose.sim.render import render_frame
from tofpose.study.columns import COLUMNS, ERROR_COLUMNS, SIGMA_COLUMNS
from tofpose.study.spec import PRESETS, Cell, StudySpec
from tofpose.study.store import chunk_name, write_chunk

#: this process's pipelines, by (catalog, preset), and how long its first frame took
_pipelines: dict[tuple[str, str], PosePipeline] = {}
_first_frame_s: float | None = None
#: the camera of this process's chunks: one for all of them, as a serial run has (it
#: keeps the pixel bearings it computed at its first frame; a new one per chunk computed
#: them again)
_camera: CameraModel | None = None
#: whether this process's BLAS is limited to one thread: done by its first chunk only
#: (the call looks through every loaded library, about a millisecond a chunk)
_blas_limited = False
#: the numba kernels in this process's tofpose modules, found when as many modules were
#: loaded as the count says (looked for again once more are: a scan of every module's
#: names, about a millisecond, not repeated at every chunk)
_kernels: tuple[int, list] = (0, [])


def frame_rng(seed: int, cell: int, frame: int) -> np.random.Generator:
    """The generator of frame ``frame`` of cell ``cell``: SeedSequence(seed).spawn's
    child (cell, frame), independent of every other frame's."""
    return np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(cell, frame)))


def kernel_load() -> dict:
    """How this process came by the numba kernels it ran so far: {"pid",
    "first_frame_s" (its first frame, which loaded them: None before one ran),
    "cache_hits", "cache_misses"} (misses are kernels this process compiled, 0 when
    every one came from the on-disk cache). The kernels load on first use, only those
    a study's frames take (no warm-up of the live loop's paths in a worker)."""
    hits = misses = 0
    for kernel in _loaded_kernels():
        hits += sum(kernel.stats.cache_hits.values())
        misses += sum(kernel.stats.cache_misses.values())
    return {
        "pid": os.getpid(),
        "first_frame_s": _first_frame_s,
        "cache_hits": hits,
        "cache_misses": misses,
    }


def _loaded_kernels() -> list:
    """The numba dispatchers bound to a name in a loaded tofpose module (one entry per
    module that binds one), looked for again only when more modules are loaded."""
    global _kernels
    if len(sys.modules) != _kernels[0]:
        from numba.core.registry import CPUDispatcher

        modules = list(sys.modules.items())
        found = [
            obj
            for name, module in modules
            if name.startswith("tofpose")
            for obj in vars(module).values()
            if isinstance(obj, CPUDispatcher)
        ]
        _kernels = (len(modules), found)
    return _kernels[1]


def _pipeline(camera: CameraModel, cell: Cell) -> PosePipeline:
    key = (cell.catalog, cell.preset)
    if key not in _pipelines:
        _pipelines[key] = PosePipeline(
            camera, BUILTIN_CATALOGS[cell.catalog](), PRESETS[cell.preset]()
        )
    return _pipelines[key]


def measure_frame(spec: StudySpec, cell: Cell, frame: int, camera: CameraModel) -> dict:
    """One frame's row (``COLUMNS``)."""
    pipe = _pipeline(camera, cell)
    rng = frame_rng(spec.seed, cell.index, frame)
    scene, sensor = draw_physics(cell.physics, rng, pipe.catalog, cell.ambient_lux)
    T = draw_pose(cell.range_m, rng, camera, cell.attitude_deg, cell.offset_fraction)
    scene = draw_background(cell.physics, scene, rng, camera, T)
    f = render_frame(camera, scene, T, sensor, rng)
    pipe.reset()
    r = pipe.process(f.gray, f.distance_mm)
    gains = scene.reflector_gains or (1.0,)
    nan = math.nan
    row = {
        "cell": cell.index,
        "frame": frame,
        "range_m": cell.range_m,
        "attitude_deg": cell.attitude_deg,
        "offset_fraction": cell.offset_fraction,
        "ambient_lux": cell.ambient_lux,
        "physics": cell.physics,
        "catalog": cell.catalog,
        "preset": cell.preset,
        "plate_reflectance": scene.plate_reflectance,
        "wall_distance_mm": nan if scene.wall_distance_mm is None else scene.wall_distance_mm,
        "blur_sigma_px": sensor.blur_sigma_px,
        "psf_halo_fraction": sensor.psf_halo_fraction,
        "gain_min": min(gains),
        "gain_max": max(gains),
        "retro_falloff_exponent": scene.retro_falloff_exponent,
        "true_range_mm": float(np.linalg.norm(T.t_mm)),
        **dict(zip(("true_x_mm", "true_y_mm", "true_z_mm"), T.t_mm.tolist(), strict=True)),
        **dict(
            zip(
                ("true_qw", "true_qx", "true_qy", "true_qz"),
                quaternion_wxyz_from_rotation(T.R).tolist(),
                strict=True,
            )
        ),
        "ok": bool(r.ok),
        "reason": r.reason,
        "n_matched": r.n_matched,
    }
    est = ("est_x_mm", "est_y_mm", "est_z_mm", "est_qw", "est_qx", "est_qy", "est_qz")
    if r.ok:
        R, t_mm, q, cov = r.R, r.t_mm, r.quaternion_wxyz, r.covariance
        if R is None or t_mm is None or q is None or cov is None:
            raise ValueError(
                "a result marked ok lacks its pose (R, t_mm, quaternion_wxyz) or covariance"
            )
        e = pose_error(R, t_mm, T.R, T.t_mm)
        sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        scale = np.array([180.0 / math.pi] * 3 + [1.0] * 3)
        row.update(zip(est, [*t_mm.tolist(), *q.tolist()], strict=True))
        row.update(zip(ERROR_COLUMNS, (e * scale).tolist(), strict=True))
        row.update(zip(SIGMA_COLUMNS, (sd * scale).tolist(), strict=True))
        row["d2"] = mahalanobis2(e, cov)
        row["attitude_error_deg"] = math.degrees(float(np.linalg.norm(e[:3])))
        row["position_error_mm"] = float(np.linalg.norm(e[3:]))
    else:
        row.update(
            dict.fromkeys(
                (
                    *est,
                    *ERROR_COLUMNS,
                    *SIGMA_COLUMNS,
                    "d2",
                    "attitude_error_deg",
                    "position_error_mm",
                ),
                nan,
            )
        )
    verdict = judge(
        [row["ok"]],
        [row["attitude_error_deg"]],
        [row["position_error_mm"]],
        [row["d2"]],
        [row["true_range_mm"]],
    )
    row.update({k: bool(v[0]) for k, v in verdict.items()})
    return row


def run_chunk(
    spec_doc: dict,
    cell_index: int,
    start: int,
    stop: int,
    store_dir: str,
    progress_topic: str | None = None,
) -> dict:
    """The task: frames [start, stop) of cell ``cell_index``, written to the store as one
    Parquet file (``store.write_chunk``: atomic, named by the chunk, so a rescheduled
    task overwrites the same file with the same rows). ``progress_topic``: the run's
    event topic, on which the frames done are reported while it runs
    (``tofpose.batch.worker.ProgressReporter``). Returns {"cell", "start", "stop",
    "frames", "seconds" (measuring), "cpu_s" (its thread's CPU time meanwhile),
    "kernel_load" (``kernel_load``)}."""
    global _first_frame_s, _blas_limited, _camera
    if not _blas_limited:
        single_threaded_blas()
        _blas_limited = True
    spec = StudySpec.from_dict(spec_doc, limits=None)  # the client checked its size
    cell = spec.cells[cell_index]
    if _camera is None:
        _camera = CameraModel()
    camera = _camera
    report = ProgressReporter(progress_topic, chunk_name(cell_index, start, stop))
    t0, cpu0 = time.perf_counter(), time.thread_time()
    rows = []
    for i in range(start, stop):
        rows.append(measure_frame(spec, cell, i, camera))
        if _first_frame_s is None:
            _first_frame_s = time.perf_counter() - t0
        report(len(rows))
    seconds, cpu_s = time.perf_counter() - t0, time.thread_time() - cpu0
    table = pa.Table.from_pylist(rows, schema=COLUMNS)
    write_chunk(store_dir, cell_index, start, stop, table)
    return {
        "cell": cell_index,
        "start": start,
        "stop": stop,
        "frames": stop - start,
        "seconds": seconds,
        "cpu_s": cpu_s,
        "kernel_load": kernel_load(),
    }
