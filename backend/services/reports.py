"""Campaign reports: CSV (one row per frame), JSON (every statistic), HTML (self-contained,
plots embedded) and PDF (the same tables and plots, matplotlib's PDF backend).

The statistics come from ``analysis.analyse`` on exactly the rows the CSV holds, so a
reader can recompute every number of the JSON from the CSV.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
from datetime import UTC, datetime

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.backends.backend_pdf import PdfPages  # noqa: E402
from sqlalchemy import select  # noqa: E402
from sqlalchemy.orm import Session  # noqa: E402

from backend.db.models import (  # noqa: E402
    CalibrationRow,
    CampaignRow,
    MeasurementRow,
    SetPointRow,
)
from backend.services.analysis import AXES, REFERENCE_PREFIX, analyse, findings  # noqa: E402
from backend.services.calibrations import calibrated_reference  # noqa: E402

POSE = AXES
CSV_COLUMNS = (
    "setpoint_index", "frame_index", "time_s", "ok", "n_matched", "residual_mm", "reason",
    *POSE,
    *(f"truth_{a}" for a in POSE),
    *(f"lab_truth_{a}" for a in POSE),
    "sigma_x_mm", "sigma_y_mm", "sigma_z_mm", "sigma_pitch_deg", "sigma_yaw_deg",
    "sigma_roll_deg",
    "setpoint_yaw_deg", "setpoint_pitch_deg", "setpoint_roll_deg", "setpoint_rail_mm",
    "encoder_yaw_deg", "encoder_pitch_deg", "encoder_roll_deg", "encoder_rail_mm",
    *(f"calibrated_truth_{a}" for a in POSE),
)  # fmt: skip
UNITS = {a: a.rsplit("_", 1)[1] for a in POSE}


class ReportError(ValueError):
    """A report that cannot be made as asked (e.g. no exact truth on real hardware)."""


def campaign_rows(
    session: Session, campaign_id: int, calibration: CalibrationRow | None = None
) -> list[dict]:
    """Every stored frame of the campaign as a dict of ``CSV_COLUMNS``; the
    ``calibrated_truth_*`` columns are filled when a calibration is given."""
    q = (
        select(MeasurementRow, SetPointRow)
        .join(SetPointRow, MeasurementRow.setpoint_id == SetPointRow.id)
        .where(SetPointRow.campaign_id == campaign_id)
        .order_by(SetPointRow.index, MeasurementRow.id)
    )
    out = []
    for m, sp in session.execute(q).all():
        enc = m.encoders or {}
        row = {
            "setpoint_index": sp.index, "frame_index": m.frame_index, "time_s": m.frame_time_s,
            "ok": int(m.ok), "n_matched": m.n_matched, "residual_mm": m.residual_mm,
            "reason": m.reason,
            "setpoint_yaw_deg": sp.yaw_deg, "setpoint_pitch_deg": sp.pitch_deg,
            "setpoint_roll_deg": sp.roll_deg, "setpoint_rail_mm": sp.rail_mm,
            "encoder_yaw_deg": enc.get("yaw"), "encoder_pitch_deg": enc.get("pitch"),
            "encoder_roll_deg": enc.get("roll"), "encoder_rail_mm": enc.get("rail"),
        }  # fmt: skip
        if calibration is not None and {"yaw", "pitch", "roll", "rail"} <= set(enc):
            ref = calibrated_reference(calibration, enc)
            row.update({f"calibrated_truth_{a}": v for a, v in ref.items()})
        for col in CSV_COLUMNS:
            if col not in row:
                row[col] = getattr(m, col, None)
        out.append(row)
    return out


def to_csv(rows: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: ("" if v is None else v) for k, v in r.items()})
    return buf.getvalue()


def jsonable(obj):
    """NaN and infinities -> None (JSON has neither), recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    return obj


def build(
    session: Session,
    campaign_id: int,
    reference: str = "lab",
    calibration: CalibrationRow | None = None,
) -> tuple[dict, list]:
    """(report dict, rows) of a campaign; ``ReportError`` when the reference is missing.
    With a ``calibration`` the reference is ``calibrated``: encoders + the calibrated mount
    and placement."""
    if calibration is not None:
        reference = "calibrated"
    row = session.get(CampaignRow, campaign_id)
    rows = campaign_rows(session, campaign_id, calibration)
    prefix = REFERENCE_PREFIX[reference]
    if rows and all(r[prefix + "x_mm"] is None for r in rows):
        raise ReportError(
            f"no {reference} reference in this campaign's frames"
            + (" (exact truth exists only on the simulator)" if reference == "exact" else "")
        )
    result = analyse(rows, row.requirements, reference)
    report = {
        "campaign": {
            "id": row.id, "name": row.name, "status": row.status, "catalog": row.catalog_name,
            "frames_per_point": row.frames_per_point, "settle_s": row.settle_s,
            "n_setpoints": len(row.setpoints),
            "n_done": sum(1 for sp in row.setpoints if sp.status == "done"),
            "generator": row.generator, "notes": row.notes,
            "started_at": row.started_at.isoformat() if row.started_at else None,
            "finished_at": row.finished_at.isoformat() if row.finished_at else None,
        },
        "generated_at": datetime.now(UTC).isoformat(),
        "calibration": (
            {"id": calibration.id, "name": calibration.name} if calibration is not None else None
        ),
        **result,
    }  # fmt: skip
    report["findings"] = findings(result)
    return jsonable(report), rows


def to_json(report: dict) -> str:
    return json.dumps(report, indent=1, allow_nan=False)


# -- plots ---------------------------------------------------------------------------------
def _arrays(rows: list[dict], reference: str) -> dict[str, np.ndarray]:
    prefix = REFERENCE_PREFIX[reference]
    ok = [r for r in rows if r["ok"]]

    def col(k):
        return np.array([np.nan if r[k] is None else float(r[k]) for r in ok], float)

    out = {"t": col("time_s"), "sp": col("setpoint_index")}
    for a in POSE:
        out[a], out["ref_" + a] = col(a), col(prefix + a)
    return out


def figures(report: dict, rows: list[dict]) -> list[tuple[str, plt.Figure]]:
    """(title, figure) of the report's plots: error time series (paper Figs. 8-13),
    measured vs reference per set-point (Fig. 14), error vs range."""
    ref = report["reference"]
    d = _arrays(rows, ref)
    figs = []
    fig, axs = plt.subplots(3, 2, figsize=(10, 7.5), sharex=True, constrained_layout=True)
    for ax, a in zip(axs.T.ravel(), POSE, strict=True):
        ax.plot(d["t"], d[a] - d["ref_" + a], ".", ms=2)
        ax.set_ylabel(f"{a.rsplit('_', 1)[0]} error ({UNITS[a]})")
        ax.grid(alpha=0.3)
    for ax in axs[-1]:
        ax.set_xlabel("frame time (s)")
    fig.suptitle(f"Error per frame against the {ref} reference")
    figs.append(("Error per frame (time series)", fig))

    fig, axs = plt.subplots(3, 2, figsize=(10, 7.5), sharex=True, constrained_layout=True)
    for ax, a in zip(axs.T.ravel(), POSE, strict=True):
        ax.plot(d["t"], d["ref_" + a], "-", color="0.6", lw=1.0, label="reference")
        ax.plot(d["t"], d[a], ".", ms=2, label="measured")
        ax.set_ylabel(f"{a.rsplit('_', 1)[0]} ({UNITS[a]})")
        ax.grid(alpha=0.3)
    axs[0, 0].legend(loc="best", fontsize=8)
    for ax in axs[-1]:
        ax.set_xlabel("frame time (s)")
    fig.suptitle("Measured pose and reference over time (steps, holds)")
    figs.append(("Measured and reference over time", fig))

    sps = report["setpoints"]
    fig, axs = plt.subplots(2, 3, figsize=(11, 6.5), constrained_layout=True)
    for ax, a in zip(axs.ravel(), POSE, strict=True):
        ref_v = np.array([sp["reference"][a] if sp["reference"][a] is not None else np.nan
                          for sp in sps], float)  # fmt: skip
        mean = ref_v + np.array([_num(sp["axes"][a]["bias"]) for sp in sps])
        ax.plot(ref_v, mean, "o", ms=4)
        lo, hi = np.nanmin(np.r_[ref_v, mean, 0.0]), np.nanmax(np.r_[ref_v, mean, 0.0])
        ax.plot([lo, hi], [lo, hi], "k--", lw=0.8)
        ax.set_xlabel(f"reference {a.rsplit('_', 1)[0]} ({UNITS[a]})")
        ax.set_ylabel(f"measured ({UNITS[a]})")
        ax.grid(alpha=0.3)
    fig.suptitle("Measured (mean per set-point) vs reference")
    figs.append(("Measured vs reference per set-point", fig))

    rng = np.array([_num(sp["reference"]["z_mm"]) for sp in sps]) / 1000.0
    fig, axs = plt.subplots(1, 2, figsize=(11, 4), constrained_layout=True)
    for ax, group, unit in ((axs[0], POSE[:3], "mm"), (axs[1], POSE[3:], "deg")):
        for a in group:
            bias = np.array([_num(sp["axes"][a]["bias"]) for sp in sps])
            std = np.array([_num(sp["axes"][a]["std"]) for sp in sps])
            ax.errorbar(rng, bias, yerr=np.nan_to_num(std), fmt="o", ms=4, capsize=2,
                        label=a.rsplit("_", 1)[0])  # fmt: skip
        ax.set_xlabel("range (reference z, m)")
        ax.set_ylabel(f"mean error +/- 1 std ({unit})")
        ax.legend()
        ax.grid(alpha=0.3)
    fig.suptitle("Error vs range")
    figs.append(("Error vs range", fig))
    return figs


def _num(v) -> float:
    return float("nan") if v is None else float(v)


def _png_b64(fig: plt.Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)
    plt.close(fig)
    return base64.b64encode(buf.getvalue()).decode()


# -- tables ----------------------------------------------------------------------------------
def _fmt(v, digits: int = 3) -> str:
    if v is None:
        return "-"
    if isinstance(v, bool):
        return "pass" if v else "FAIL"
    if isinstance(v, float):
        return f"{v:.{digits}g}" if math.isfinite(v) else "-"
    return str(v)


STAT_COLUMNS = ("n", "n_removed", "bias", "std", "rms", "max_abs", "three_sigma",
                "predicted_sigma", "sigma_ratio", "requirement", "passed")  # fmt: skip
PAPER_COLUMNS = ("average", "maximum", "minimum", "fluctuation")


def table_rows(axes: dict[str, dict], columns) -> list[list[str]]:
    return [[a] + [_fmt(axes[a][c]) for c in columns] for a in POSE]


def to_html(report: dict, rows: list[dict]) -> str:
    c = report["campaign"]
    esc = html.escape
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>Campaign {c['id']}: {esc(c['name'])}</title>",
        "<style>body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
        "table{border-collapse:collapse;margin:0.5em 0 1.5em}td,th{border:1px solid #bbb;"
        "padding:3px 7px;text-align:right}th{background:#eee}td:first-child{text-align:left}"
        ".fail{color:#b00;font-weight:bold}.pass{color:#070}</style></head><body>",
        f"<h1>Campaign {c['id']}: {esc(c['name'])}</h1>",
        f"<p>Status <b>{esc(c['status'])}</b>, catalog {esc(c['catalog'])}, "
        f"{c['n_done']} of {c['n_setpoints']} set-points measured, {c['frames_per_point']} "
        f"frames per set-point, settle {c['settle_s']:g} s. Reference: "
        f"<b>{esc(_reference_label(report))}</b>. {report['n_ok']} of {report['n_frames']} "
        "frames gave a pose.</p>",
        f"<p><i>{esc(report['rule'])}</i></p>",
        "<h2>Findings</h2><ul>",
        *(f"<li>{esc(f)}</li>" for f in report["findings"]),
        "</ul>",
        "<h2>Whole campaign</h2>",
        _html_table(
            ["axis", *STAT_COLUMNS], table_rows(report["overall"]["axes"], STAT_COLUMNS)
        ),  # fmt: skip
    ]
    for title, fig in figures(report, rows):
        parts.append(f"<h2>{esc(title)}</h2><img alt='{esc(title)}' "
                     f"src='data:image/png;base64,{_png_b64(fig)}'>")  # fmt: skip
    parts.append("<h2>Per set-point</h2>")
    for sp in report["setpoints"]:
        parts.append(
            f"<h3>Set-point {sp['setpoint_index']} ({sp['n_ok']}/{sp['n_frames']} frames with "
            f"a pose; {_fmt(sp['passed'])})</h3>"
        )
        parts.append(_html_table(["axis", *STAT_COLUMNS], table_rows(sp["axes"], STAT_COLUMNS)))
        parts.append(_html_table(["axis (measured)", *PAPER_COLUMNS],
                                 table_rows(sp["axes"], PAPER_COLUMNS)))  # fmt: skip
    parts.append(f"<p>Generated {esc(report['generated_at'])} by tofpose.</p></body></html>")
    return "\n".join(parts)


def _reference_label(report: dict) -> str:
    cal = report.get("calibration")
    if cal:
        return f"calibrated (encoders + calibration {cal['id']} '{cal['name']}')"
    labels = {"lab": "lab (encoders + nominal geometry)", "exact": "exact (the rendered pose)"}
    return labels.get(report["reference"], report["reference"])


def _html_table(header: list[str], body: list[list[str]]) -> str:
    def cell(v: str) -> str:
        cls = " class='fail'" if v == "FAIL" else (" class='pass'" if v == "pass" else "")
        return f"<td{cls}>{html.escape(v)}</td>"

    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    rows = "".join("<tr>" + "".join(cell(v) for v in r) + "</tr>" for r in body)
    return f"<table><tr>{head}</tr>{rows}</table>"


def to_pdf(report: dict, rows: list[dict]) -> bytes:
    """The summary, the whole-campaign table, the plots and the per-set-point tables."""
    buf = io.BytesIO()
    c = report["campaign"]
    with PdfPages(buf) as pdf:
        fig = plt.figure(figsize=(11.7, 8.3))
        fig.text(0.05, 0.94, f"Campaign {c['id']}: {c['name']}", fontsize=18, weight="bold")
        lines = [
            f"Status {c['status']}, catalog {c['catalog']}, {c['n_done']} of "
            f"{c['n_setpoints']} set-points, {c['frames_per_point']} frames each; reference "
            f"{_reference_label(report)}; {report['n_ok']} of {report['n_frames']} frames "
            "with a pose.",
            report["rule"],
            *("- " + f for f in report["findings"]),
        ]
        fig.text(0.05, 0.9, "\n".join(lines), fontsize=8.5, va="top", wrap=True)
        ax = fig.add_axes((0.05, 0.05, 0.9, 0.45))
        ax.axis("off")
        tab = ax.table(cellText=table_rows(report["overall"]["axes"], STAT_COLUMNS),
                       colLabels=["axis", *STAT_COLUMNS], loc="upper center")  # fmt: skip
        tab.auto_set_font_size(False)
        tab.set_fontsize(7.5)
        tab.scale(1.0, 1.4)
        pdf.savefig(fig)
        plt.close(fig)
        for _title, f in figures(report, rows):
            pdf.savefig(f)
            plt.close(f)
        # Per set-point: one compact table (bias / std per axis and pass), many set-points
        # a page; the full per-set-point tables are in the HTML and JSON.
        header = ["set-point", "frames ok"] + [f"{a.rsplit('_', 1)[0]} {q}" for a in POSE
                                                for q in ("bias", "std")] + ["result"]  # fmt: skip
        body = [
            [str(sp["setpoint_index"]), f"{sp['n_ok']}/{sp['n_frames']}"]
            + [_fmt(sp["axes"][a][q]) for a in POSE for q in ("bias", "std")]
            + [_fmt(sp["passed"])]
            for sp in report["setpoints"]
        ]
        per_page = 30
        for k in range(0, len(body), per_page):
            fig = plt.figure(figsize=(11.7, 8.3))
            ax = fig.add_axes((0.03, 0.03, 0.94, 0.9))
            ax.axis("off")
            ax.set_title(f"Per set-point (errors against the {report['reference']} reference;"
                         " mm and deg)", fontsize=10)  # fmt: skip
            tab = ax.table(cellText=body[k : k + per_page], colLabels=header, loc="upper center")
            tab.auto_set_font_size(False)
            tab.set_fontsize(6.5)
            pdf.savefig(fig)
            plt.close(fig)
    return buf.getvalue()
