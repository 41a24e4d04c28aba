"""A study's frames: each depends on (seed, cell, frame) alone, and is judged against the
truth it was rendered at."""

import math

import numpy as np

from tofpose.core.camera import CameraModel
from tofpose.study.frames import frame_rng, measure_frame
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
