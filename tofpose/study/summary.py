"""Per-cell statistics of a study (``summary.json``), from the stored frames.

Per cell: frames, poses (ok), no pose, success %, wrong and confidently wrong poses,
share of poses beyond 3 reported sigmas, mean NEES / 6 (the rules of
``tofpose.lab.pose_judgement``); per error component (``AXES``: rotation vector deg, position
mm) over the poses: bias (mean), std, RMS and the RMS of error over reported sigma
(1 = a right covariance); attitude and position error p50 / p95 / p99 over the poses
(every pose, not only the successes: a 99th percentile of an envelope has to see the
bad ones); failure reasons by kind; and the verdict against the spec's requirements
(``tofpose.study.verdict``: per axis the deciding percentile of |error|, pass / fail, the
failure modes and the main one). The study's verdict in one paragraph heads the
summary. Computed in one order (cells, then frames), so the same stored rows give the
same bits.

``success_pct`` is ``tofpose.lab.pose_judgement``'s gross rule (within 1 deg and
max(20 mm, 0.5 % of the range), the rule every bench figure uses), not the
requirements: ``verdict.within_all_pct`` is the share of frames within every
requirement.
"""

from __future__ import annotations

import math
from collections import Counter
from dataclasses import asdict

import numpy as np
import pyarrow as pa

from tofpose.lab.pose_judgement import AXES
from tofpose.study.axis_errors import requirement_axis_errors
from tofpose.study.columns import ERROR_COLUMNS, SIGMA_COLUMNS
from tofpose.study.spec import StudyRequirements, StudySpec
from tofpose.study.verdict import judge_cell, reason_kind, study_verdict

__all__ = ["PERCENTILES", "cell_statistics", "reason_kind", "summarise"]

PERCENTILES = (50, 95, 99)


def _num(x: float | np.floating) -> float | None:
    return float(x) if math.isfinite(x) else None


def _percentiles(values: np.ndarray) -> dict[str, float | None]:
    if not len(values):
        return {f"p{q}": None for q in PERCENTILES}
    return {f"p{q}": _num(np.percentile(values, q)) for q in PERCENTILES}


def cell_statistics(
    columns: dict[str, np.ndarray], requirements: StudyRequirements | None = None
) -> dict:
    """The statistics (module docstring) of one cell's rows (column -> (N,) array), and
    its verdict against ``requirements`` (None: the defaults)."""
    n = len(columns["frame"])
    ok = columns["ok"].astype(bool)
    n_ok = int(ok.sum())
    d2 = columns["d2"][ok]
    d2 = d2[np.isfinite(d2)]
    err = np.stack([columns[c][ok] for c in ERROR_COLUMNS], axis=1) if n_ok else np.zeros((0, 6))
    sig = np.stack([columns[c][ok] for c in SIGMA_COLUMNS], axis=1) if n_ok else np.zeros((0, 6))
    axes = {}
    for k, a in enumerate(AXES):
        e = err[:, k]
        axes[a] = {
            "bias": _num(np.mean(e)) if n_ok else None,
            "std": _num(np.std(e, ddof=1)) if n_ok > 1 else None,
            "rms": _num(np.sqrt(np.mean(e**2))) if n_ok else None,
            "spread_over_sigma": _num(np.sqrt(np.mean((e / sig[:, k]) ** 2))) if n_ok else None,
        }
    failed = Counter(reason_kind(r) for r, o in zip(columns["reason"], ok, strict=True) if not o)
    verdict = judge_cell(
        requirement_axis_errors(columns),
        [str(r or "") for r in columns["reason"]],
        requirements or StudyRequirements(),
    )
    return {
        "verdict": verdict.to_dict(),
        "frames": n,
        "poses": n_ok,
        "no_pose": n - n_ok,
        "success_pct": _num(100.0 * columns["success"].sum() / n) if n else None,
        "wrong": int(columns["wrong"].sum()),
        "confidently_wrong": int(columns["confidently_wrong"].sum()),
        "beyond_3sigma_pct": _num(100.0 * columns["beyond_3sigma"].sum() / n_ok) if n_ok else None,
        "nees_over_6": _num(np.mean(d2) / 6.0) if len(d2) else None,
        "attitude_error_deg": _percentiles(columns["attitude_error_deg"][ok]),
        "position_error_mm": _percentiles(columns["position_error_mm"][ok]),
        "axes": axes,
        "failures": dict(sorted(failed.items())),
    }


def summarise(spec: StudySpec, table: pa.Table) -> dict:
    """``summary.json``: the spec's name and size, per cell its axes and statistics, and
    the statistics of all frames together. ``table``: the stored rows (``store``)."""
    cols = {name: table.column(name).to_numpy(zero_copy_only=False) for name in table.column_names}
    cell_of = cols["cell"]
    cells = []
    for c in spec.cells:
        sel = cell_of == c.index
        stats = cell_statistics({k: v[sel] for k, v in cols.items()}, spec.requirements)
        cells.append(
            {
                "cell": c.index,
                "label": c.label,
                "range_m": c.range_m,
                "attitude_deg": c.attitude_deg,
                "offset_fraction": c.offset_fraction,
                "ambient_lux": c.ambient_lux,
                "physics": c.physics,
                "catalog": c.catalog,
                "preset": c.preset,
                "frames_planned": spec.frames_per_cell,
                **stats,
            }
        )
    return {
        "name": spec.name,
        "seed": spec.seed,
        "frames_planned": spec.n_frames,
        "frames_stored": int(table.num_rows),
        "complete": int(table.num_rows) == spec.n_frames,
        "requirements": asdict(spec.requirements),
        "verdict": study_verdict(cells, spec.requirements),
        "all": cell_statistics(cols, spec.requirements) if table.num_rows else None,
        "cells": cells,
    }
