"""Campaign report speed: a 6000-frame stability run (the paper's length, §6.3) and a
50-set-point grid of 30 frames, each format generated from the database, medians over
repeated runs on one core.

The frames are synthetic rows (pose = reference + Gaussian noise of the simulator's size
at 5.7 m) written straight into a temporary SQLite database: the report's work depends
on the number of rows and set-points, not on how they were measured.

Run: ``python bench/reports.py [--repeats N]``.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from backend.db.engine import make_engine, make_session_factory, upgrade_database  # noqa: E402
from backend.db.models import MeasurementRow, SetPointRow  # noqa: E402
from backend.services.campaigns.campaigns import create_campaign  # noqa: E402
from backend.services.reports.reports import build, to_csv, to_html, to_json, to_pdf  # noqa: E402
from bench._common import single_core, table  # noqa: E402

REQ = {"x_mm": 6.0, "y_mm": 6.0, "z_mm": 28.3, "pitch_deg": 0.15, "yaw_deg": 0.15, "roll_deg": 0.15}
NOISE = {
    "x_mm": 0.3,
    "y_mm": 0.3,
    "z_mm": 1.0,
    "pitch_deg": 0.05,
    "yaw_deg": 0.05,
    "roll_deg": 0.01,
}


def make_campaign(sessions, name: str, n_points: int, frames: int, seed: int) -> int:
    rng = np.random.default_rng(seed)
    with sessions() as s:
        setpoints = [
            {"yaw": float(i % 10), "rail": 9000.0 + 100.0 * (i // 10)} for i in range(n_points)
        ]
        row = create_campaign(
            s,
            name=name,
            catalog_name="paper-target",
            setpoints=setpoints,
            frames_per_point=frames,
            settle_s=1.0,
            lock_timeout_s=5.0,
            requirements=REQ,
        )
        cid = row.id
        for sp in s.query(SetPointRow).filter_by(campaign_id=cid):
            ref = {
                "x_mm": 0.0,
                "y_mm": 0.0,
                "z_mm": 15000.0 - sp.rail_mm,
                "pitch_deg": 0.0,
                "yaw_deg": -sp.yaw_deg,
                "roll_deg": 0.0,
            }
            rows = []
            for k in range(frames):
                m = MeasurementRow(
                    setpoint_id=sp.id,
                    frame_index=k,
                    frame_time_s=0.1 * k,
                    ok=True,
                    reason="",
                    n_matched=8,
                    residual_mm=0.5,
                )
                for a, v in ref.items():
                    setattr(m, a, v + rng.normal(0, NOISE[a]))
                    setattr(m, "lab_truth_" + a, v)
                    setattr(m, "truth_" + a, v)
                    setattr(m, "sigma_" + a, NOISE[a])
                rows.append(m)
            s.add_all(rows)
            sp.status = "done"
        s.commit()
    return cid


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    single_core()
    with tempfile.TemporaryDirectory() as tmp:
        engine = make_engine(f"sqlite:///{Path(tmp) / 'bench.db'}")
        upgrade_database(engine)
        sessions = make_session_factory(engine)
        cases = [
            ("stability, 1 x 6000 frames", make_campaign(sessions, "stab", 1, 6000, 0)),
            ("grid, 50 x 30 frames", make_campaign(sessions, "grid", 50, 30, 1)),
        ]
        rows_out = []
        for label, cid in cases:
            times: dict[str, list[float]] = {
                k: [] for k in ("statistics", "csv", "json", "html", "pdf")
            }
            for _ in range(args.repeats):
                with sessions() as s:
                    t0 = time.perf_counter()
                    rep, rows = build(s, cid)
                    times["statistics"].append(time.perf_counter() - t0)
                for fmt, fn, fn_args in (
                    ("csv", to_csv, (rows,)),
                    ("json", to_json, (rep,)),
                    ("html", to_html, (rep, rows)),
                    ("pdf", to_pdf, (rep, rows)),
                ):
                    t0 = time.perf_counter()
                    fn(*fn_args)
                    times[fmt].append(time.perf_counter() - t0)
            med = {k: float(np.median(v)) for k, v in times.items()}
            rows_out.append(
                [label]
                + [f"{med[k]:.2f}" for k in times]
                + [f"{med['statistics'] + med['pdf']:.2f}"]
            )
        engine.dispose()
    print(f"Campaign report time in s, median of {args.repeats} runs (one core):\n")
    print(
        table(
            [
                "campaign",
                "statistics (DB read + analysis)",
                "csv",
                "json",
                "html",
                "pdf",
                "pdf total",
            ],
            rows_out,
        )
    )


if __name__ == "__main__":
    main()
