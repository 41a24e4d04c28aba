"""A study's frames: each depends on (seed, cell, frame) alone, and is judged against the
truth it was rendered at. A chunk's fixed costs are paid once per process: its BLAS
limit, its camera (and the pixel bearings it keeps), and the search for the kernels
whose cache loads it reports."""

import math
import sys
import types

import numpy as np
from numba.core.registry import CPUDispatcher
from threadpoolctl import threadpool_info

import tofpose.study.frames as frames
from tofpose.core.camera import CameraModel
from tofpose.stages.extraction.kernels.levels import checked_frame
from tofpose.study.frames import frame_rng, kernel_load, measure_frame, run_chunk
from tofpose.study.spec import StudySpec

SPEC = StudySpec.from_dict(
    {
        "seed": 7,
        "frames_per_cell": 4,
        "grid": {"range_m": [2.0, 3.0], "physics": ["ideal", "grey plate"]},
    }
)


def test_a_frame_depends_on_seed_cell_and_frame_only():
    cam = CameraModel()
    cell = SPEC.cells[3]
    a = measure_frame(SPEC, cell, 2, cam)
    measure_frame(SPEC, SPEC.cells[0], 0, cam)  # other work in between changes nothing
    b = measure_frame(SPEC, cell, 2, cam)
    assert a == b or all(
        (x == y) or (isinstance(x, float) and math.isnan(x) and math.isnan(y))
        for x, y in zip(a.values(), b.values(), strict=True)
    )
    c = measure_frame(SPEC, cell, 3, cam)
    assert c["true_x_mm"] != a["true_x_mm"]
    # the generators of different frames and cells are different streams
    draws = {frame_rng(7, ci, fi).random() for ci in range(2) for fi in range(3)}
    assert len(draws) == 6


def test_rows_are_judged_against_the_drawn_truth():
    cam = CameraModel()
    cell = SPEC.cells[2]  # 3 m, ideal
    assert (cell.range_m, cell.physics) == (3.0, "ideal")
    row = measure_frame(SPEC, cell, 0, cam)
    assert abs(row["true_range_mm"] - 3000.0) < 1e-6
    assert row["ok"] and row["success"] and not row["wrong"]
    est = np.array([row["est_x_mm"], row["est_y_mm"], row["est_z_mm"]])
    true = np.array([row["true_x_mm"], row["true_y_mm"], row["true_z_mm"]])
    assert np.linalg.norm(est - true) == np.float64(row["position_error_mm"])
    assert row["attitude_error_deg"] < 0.5
    err = np.array([row[f"err_{a}_deg"] for a in ("rx", "ry", "rz")])
    assert abs(np.linalg.norm(err) - row["attitude_error_deg"]) < 1e-9
    grey = measure_frame(SPEC, SPEC.cells[1], 0, cam)  # 2 m, grey plate: no wall
    assert 0.25 <= grey["plate_reflectance"] <= 0.6 and math.isnan(grey["wall_distance_mm"])


def _scanned_kernel_load() -> tuple[int, int]:
    """(cache hits, misses) summed over every dispatcher bound in a loaded tofpose module,
    looked up afresh: what ``kernel_load`` reports."""
    hits = misses = 0
    for name, module in list(sys.modules.items()):
        if name.startswith("tofpose"):
            for obj in vars(module).values():
                if isinstance(obj, CPUDispatcher):
                    hits += sum(obj.stats.cache_hits.values())
                    misses += sum(obj.stats.cache_misses.values())
    return hits, misses


def test_kernel_load_counts_the_kernels_of_modules_loaded_after_its_last_call(monkeypatch):
    checked_frame(np.zeros((1, 1), np.uint16), np.zeros((1, 1), np.float32))  # one load
    before = kernel_load()
    assert (before["cache_hits"], before["cache_misses"]) == _scanned_kernel_load()
    assert before["cache_hits"] + before["cache_misses"] > 0
    # a module loaded later that binds a kernel: its loads count once more
    late = types.ModuleType("tofpose._late_kernels")
    late.kernel = checked_frame  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, late.__name__, late)
    after = kernel_load()
    assert (after["cache_hits"], after["cache_misses"]) == _scanned_kernel_load()
    own = sum(checked_frame.stats.cache_hits.values()) + sum(
        checked_frame.stats.cache_misses.values()
    )
    assert own > 0
    total = after["cache_hits"] + after["cache_misses"]
    assert total == before["cache_hits"] + before["cache_misses"] + own


def test_chunks_run_with_one_blas_thread_limited_by_the_first_chunk_only(monkeypatch, tmp_path):
    calls = []
    limit = frames.single_threaded_blas
    monkeypatch.setattr(frames, "single_threaded_blas", lambda: calls.append(limit()))
    monkeypatch.setattr(frames, "_blas_limited", False)  # as in a new worker process
    doc = SPEC.to_dict()
    for start in (0, 1, 2):
        assert run_chunk(doc, 2, start, start + 1, str(tmp_path))["frames"] == 1
    assert len(calls) == 1
    blas = [lib for lib in threadpool_info() if lib["user_api"] == "blas"]
    assert blas and all(lib["num_threads"] == 1 for lib in blas)


def test_chunks_of_a_process_share_one_camera(monkeypatch, tmp_path):
    made = []

    def counted_camera():
        made.append(CameraModel())
        return made[-1]

    monkeypatch.setattr(frames, "CameraModel", counted_camera)
    monkeypatch.setattr(frames, "_camera", None)  # as in a new worker process
    doc = SPEC.to_dict()
    rows = [run_chunk(doc, 2, start, start + 1, str(tmp_path)) for start in (0, 1, 2)]
    assert [r["frames"] for r in rows] == [1, 1, 1]
    assert len(made) == 1
    # the bearings the first chunk computed are kept for the next
    assert "pixel_bearings" in made[0]._cache
