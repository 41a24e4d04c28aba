"""Study rows with known errors, for the verdict and report tests: the store's columns
(``tofpose.study.columns.COLUMNS``) of frames whose true attitude faces the camera and
whose estimate is off by a known facing pitch (deg) and position (mm)."""

from __future__ import annotations

import math

import numpy as np
import pyarrow as pa

from tofpose.core.geometry import FACING, quaternion_wxyz_from_rotation, rotation_from_euler_deg
from tofpose.study.columns import COLUMNS


def frame_row(cell: int, frame: int, *, pitch_deg=0.0, dz_mm=0.0, ok=True, reason="") -> dict:
    """One frame of ``cell``: the truth 3 m away facing the camera; the estimate off by
    ``pitch_deg`` in facing pitch and ``dz_mm`` in z; or no pose (``ok`` False) with
    ``reason``."""
    row = {name: math.nan for name in COLUMNS.names}
    q_true = quaternion_wxyz_from_rotation(FACING)
    R_est = rotation_from_euler_deg(pitch_deg, 0.0, 0.0) @ FACING
    row.update(
        cell=cell,
        frame=frame,
        range_m=3.0,
        attitude_deg=0.0,
        offset_fraction=0.0,
        ambient_lux=1000.0,
        physics="ideal",
        catalog="paper-target",
        preset="default",
        true_range_mm=3000.0,
        true_x_mm=0.0,
        true_y_mm=0.0,
        true_z_mm=3000.0,
        ok=ok,
        reason=reason,
        n_matched=8 if ok else 0,
        success=ok,
        wrong=False,
        beyond_3sigma=False,
        confidently_wrong=False,
    )
    row.update(zip(("true_qw", "true_qx", "true_qy", "true_qz"), q_true.tolist(), strict=True))
    if ok:
        q_est = quaternion_wxyz_from_rotation(R_est)
        row.update(zip(("est_qw", "est_qx", "est_qy", "est_qz"), q_est.tolist(), strict=True))
        row.update(est_x_mm=0.0, est_y_mm=0.0, est_z_mm=3000.0 + dz_mm)
        row.update(err_rx_deg=pitch_deg, err_ry_deg=0.0, err_rz_deg=0.0)
        row.update(err_x_mm=0.0, err_y_mm=0.0, err_z_mm=dz_mm)
        for k in ("sigma_rx_deg", "sigma_ry_deg", "sigma_rz_deg"):
            row[k] = 0.1
        for k in ("sigma_x_mm", "sigma_y_mm", "sigma_z_mm"):
            row[k] = 5.0
        row.update(d2=1.0, attitude_error_deg=abs(pitch_deg), position_error_mm=abs(dz_mm))
    return row


def table(rows: list[dict]) -> pa.Table:
    return pa.Table.from_pylist(rows, schema=COLUMNS)


def column_dict(rows: list[dict]) -> dict[str, np.ndarray]:
    t = table(rows)
    return {n: t.column(n).to_numpy(zero_copy_only=False) for n in t.column_names}
