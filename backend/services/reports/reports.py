"""Campaign reports: CSV (one row per frame), JSON (every statistic), HTML (self-contained,
plots embedded) and PDF (the same sections, matplotlib's PDF backend: ``report_pdf``).

The statistics come from ``analysis.analyse`` on exactly the rows the CSV holds, so a
reader can recompute every number of the JSON from the CSV. What the HTML and PDF say
(verdict, findings, tables with human headers) is built once in ``report_content``; the
plots are in ``report_plots``.
"""

from __future__ import annotations

import base64
import csv
import html
import io
import json
import math
from datetime import UTC, datetime
from typing import TYPE_CHECKING

from sqlalchemy import select
from sqlalchemy.orm import Session

from backend.db.models import (
    CalibrationRow,
    CampaignRow,
    MeasurementRow,
    SetPointRow,
)
from backend.services.calibrations import calibrated_reference
from backend.services.reports import report_content as rc
from backend.services.reports import report_pdf
from backend.services.reports.analysis import AXES, REFERENCE_PREFIX, analyse
from backend.services.reports.dynamic_analysis import analyse_dynamic, is_static
from backend.services.reports.report_camera import (
    SETTING_COLUMNS,
    camera_groups,
    camera_plots,
    camera_table,
    metadata_text,
    row_setting,
)
from backend.services.reports.report_dynamic import (
    dynamic_findings,
    dynamic_plots,
    dynamic_tables,
)
from backend.services.reports.report_plots import NO_PLOTS, evidence_plots, standalone
from tofpose.lab.relative_state import STATE_COLUMNS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

POSE = AXES
CSV_COLUMNS = (
    "setpoint_index",
    "frame_index",
    "time_s",
    "ok",
    "n_matched",
    "residual_mm",
    "reason",
    *POSE,
    *(f"truth_{a}" for a in POSE),
    *(f"reference_{a}" for a in POSE),
    "sigma_x_mm",
    "sigma_y_mm",
    "sigma_z_mm",
    "sigma_pitch_deg",
    "sigma_yaw_deg",
    "sigma_roll_deg",
    "setpoint_yaw_deg",
    "setpoint_pitch_deg",
    "setpoint_roll_deg",
    "setpoint_rail_mm",
    "encoder_yaw_deg",
    "encoder_pitch_deg",
    "encoder_roll_deg",
    "encoder_rail_mm",
    *(f"calibrated_reference_{a}" for a in POSE),
    *STATE_COLUMNS,
    "in_motion",
    "integration_time_us",
    "setpoint_integration_time_us",
    "setpoint_modulation_frequency_mhz",
    "pixel_fit",
)
"""The report CSV's columns. ``truth_*``: the pose the simulator rendered (empty on real
hardware); ``reference_*``: the lab's reference (encoders + nominal geometry);
``calibrated_reference_*``: encoders + a calibration (docs/interop.md, "Names: truth and
reference"); ``pixel_fit``: "ok" when the pose is the pixel-level fit's, else why the
centroid pose stands, empty when the fit did not run. ``report_csv.read_csv`` also reads
the older names."""
MEASUREMENT_COLUMN = {f"reference_{a}": f"lab_truth_{a}" for a in POSE}
"""The stored measurement's attribute behind a CSV column where the two names differ
(the database keeps the older name: renaming it would need a migration)."""


class ReportError(ValueError):
    """A report that cannot be made as asked (e.g. no truth on real hardware)."""


def campaign_rows(
    session: Session, campaign_id: int, calibration: CalibrationRow | None = None
) -> list[dict]:
    """Every stored frame of the campaign as a dict of ``CSV_COLUMNS``; the
    ``calibrated_reference_*`` columns are filled when a calibration is given."""
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
            "setpoint_index": sp.index,
            "frame_index": m.frame_index,
            "time_s": m.frame_time_s,
            "ok": int(m.ok),
            "n_matched": m.n_matched,
            "residual_mm": m.residual_mm,
            "reason": m.reason,
            "setpoint_yaw_deg": sp.yaw_deg,
            "setpoint_pitch_deg": sp.pitch_deg,
            "setpoint_roll_deg": sp.roll_deg,
            "setpoint_rail_mm": sp.rail_mm,
            "encoder_yaw_deg": enc.get("yaw"),
            "encoder_pitch_deg": enc.get("pitch"),
            "encoder_roll_deg": enc.get("roll"),
            "encoder_rail_mm": enc.get("rail"),
            "in_motion": None if m.in_motion is None else int(m.in_motion),
            **{col: (sp.camera or {}).get(k) for k, col in SETTING_COLUMNS.items()},
        }
        if calibration is not None and {"yaw", "pitch", "roll", "rail"} <= set(enc):
            ref = calibrated_reference(calibration, enc)
            row.update({f"calibrated_reference_{a}": v for a, v in ref.items()})
        for col in CSV_COLUMNS:
            if col not in row:
                row[col] = getattr(m, MEASUREMENT_COLUMN.get(col, col), None)
        out.append(row)
    return out


def to_csv(rows: list[dict]) -> str:
    """One line per frame, the columns of ``CSV_COLUMNS``."""
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
    if reference == "exact":  # the older name of the truth
        reference = "truth"
    row = session.get(CampaignRow, campaign_id)
    if row is None:  # the routes and the command look it up first
        raise LookupError(f"no campaign with id {campaign_id}")
    rows = campaign_rows(session, campaign_id, calibration)
    prefix = REFERENCE_PREFIX[reference]
    if rows and all(r[prefix + "x_mm"] is None for r in rows):
        raise ReportError(
            f"no {reference} reference in this campaign's frames"
            + (
                " (the truth, the pose a simulator rendered, exists only on the simulator or in"
                " a replayed recording's /truth)"
                if reference == "truth"
                else ""
            )
        )
    static = [r for r in rows if is_static(r)]
    result = analyse(static, row.requirements, reference)
    report = {
        "campaign": {
            "id": row.id,
            "name": row.name,
            "status": row.status,
            "catalog": row.catalog_name,
            "frames_per_point": row.frames_per_point,
            "settle_s": row.settle_s,
            "n_setpoints": len(row.setpoints),
            "n_done": sum(1 for sp in row.setpoints if sp.status == "done"),
            "generator": row.generator,
            "camera_sweep": row.camera_sweep,
            "notes": row.notes,
            "operator": row.operator,
            "target_name": row.target_name,
            "camera_model": row.camera_model,
            "camera_serial": row.camera_serial,
            "camera_firmware": row.camera_firmware,
            "started_at": row.started_at.isoformat() if row.started_at else None,
            "finished_at": row.finished_at.isoformat() if row.finished_at else None,
        },
        "generated_at": datetime.now(UTC).isoformat(),
        "calibration": calibration_summary(calibration) if calibration is not None else None,
        **result,
    }
    _add_commanded(report["setpoints"], rows)
    report["camera_settings"] = camera_groups(static, report["setpoints"], reference)
    report["dynamic"] = analyse_dynamic(rows, reference)
    report["findings"] = rc.findings(report) + dynamic_findings(report)
    return jsonable(report), rows


def calibration_summary(calibration: CalibrationRow) -> dict:
    """The calibration a report's reference uses, with its own 1-sigma: the largest
    per-axis sigma of the camera mount and of the target placement (deg, mm), the
    reference's uncertainty that the errors of the report include."""
    s = [float(v) for v in calibration.sigmas]
    return {
        "id": calibration.id,
        "name": calibration.name,
        "mount_sigma_deg": max(s[0:3]),
        "mount_sigma_mm": max(s[3:6]),
        "placement_sigma_deg": max(s[6:9]),
        "placement_sigma_mm": max(s[9:12]),
    }


def _add_commanded(setpoints: list[dict], rows: list[dict]) -> None:
    """Each set-point's commanded axes (``yaw``, ``pitch``, ``roll`` deg, ``rail`` mm; None
    for an axis it left alone) and camera setting (``camera``, None for none), from its
    first frame's row."""
    first: dict[int, dict] = {}
    for r in rows:
        first.setdefault(int(r["setpoint_index"]), r)
    for sp in setpoints:
        r = first.get(sp["setpoint_index"], {})
        sp["commanded"] = {name: r.get(col) for name, col in rc.COMMANDED_AXES}
        sp["camera"] = row_setting(r) or None


def to_json(report: dict) -> str:
    """Every statistic of ``build``, NaN as null."""
    return json.dumps(report, indent=1, allow_nan=False)


# -- HTML ------------------------------------------------------------------------------------
STYLE = (
    "body{font-family:sans-serif;max-width:1150px;margin:2em auto;color:#222;line-height:1.35}"
    "table{border-collapse:collapse;margin:0.3em 0 1.2em}td,th{border:1px solid #bbb;"
    "padding:3px 7px;text-align:right}th{background:#e6e6e6;font-size:0.9em}"
    "td:first-child{text-align:left}caption{text-align:left;font-weight:bold;padding:2px 0}"
    ".fail{color:#b00000;font-weight:bold}.pass{color:#2a7d2a}.note{color:#555;"
    "font-size:0.9em}.verdict{font-size:1.25em;font-weight:bold}.bar{display:inline-block;"
    "width:120px;height:0.8em;background:#eee;position:relative;vertical-align:middle}"
    ".bar span{display:block;height:100%}.bar i{position:absolute;top:-2px;bottom:-2px;"
    "border-left:1px dashed #000}img{max-width:100%}"
)


def _html_table(t: rc.Table, bars: dict[int, float] | None = None) -> str:
    """A ``<table>``; cells marked in ``t.status`` get the pass / fail class; ``bars``
    (row -> share of the requirement) draws a bar in the row's fourth cell."""
    esc = html.escape

    def cell(r: int, c: int, v: str) -> str:
        state = t.status.get((r, c))
        cls = "" if state is None else " class='pass'" if state else " class='fail'"
        body = esc(v)
        if bars is not None and c == 3 and math.isfinite(bars.get(r, math.nan)):
            width = min(100.0, bars[r] * 100.0 / 1.5)  # the bar spans 0-150 %
            colour = "#b00000" if bars[r] > 1.0 else "#2a7d2a"
            body = (
                f"<span class='bar'><span style='width:{width:.0f}%;background:{colour}'>"
                f"</span><i style='left:{100 / 1.5:.0f}%'></i></span> {body}"
            )
        return f"<td{cls}>{body}</td>"

    cap = f"<caption>{esc(t.caption)}</caption>" if t.caption else ""
    head = "".join(f"<th>{esc(h)}</th>" for h in t.header)
    body = "".join(
        "<tr>" + "".join(cell(r, c, v) for c, v in enumerate(row)) + "</tr>"
        for r, row in enumerate(t.rows)
    )
    return f"<table>{cap}<tr>{head}</tr>{body}</table>"


def _html_verdict(report: dict) -> list[str]:
    esc = html.escape
    cls = {True: "pass", False: "fail"}.get(report["overall"]["passed"], "")
    bars = {i: v.share for i, v in enumerate(rc.axis_verdicts(report))}
    return [
        "<h2>Verdict</h2>",
        f"<p class='verdict {cls}'>{esc(rc.verdict_line(report))}</p>",
        _html_table(rc.verdict_table(report), bars),
        f"<p class='note'>{esc(rc.requirement_source(report))}</p>",
    ]


def _html_setpoint_details(report: dict) -> list[str]:
    """The appendix: every statistic and the measured-value table of each set-point."""
    parts = ["<h2>Appendix: per set-point statistics</h2>"]
    for sp in report["setpoints"]:
        commanded = rc.commanded_text(sp.get("commanded") or {})
        parts.append(
            f"<h3>Set-point {sp['setpoint_index']} (commanded {html.escape(commanded)}; "
            f"{sp['n_ok']} of {sp['n_frames']} frames with a pose; {rc.fmt(sp['passed'])})</h3>"
        )
        parts += [_html_table(t) for t in rc.statistics_tables(sp["axes"])]
        for t in rc.measured_tables(sp["axes"]):
            t.caption = t.caption.replace("(", "measured values (", 1)
            parts.append(_html_table(t))
    return parts


def to_html(report: dict, rows: list[dict]) -> str:
    """The report as one self-contained HTML page, in the PDF's order: summary, verdict,
    findings, statistics, per-set-point table, plots; then every set-point in detail."""
    esc = html.escape
    title = rc.title(report)
    findings = report["findings"] or ["Nothing to add to the verdict."]
    parts = [
        "<!DOCTYPE html><html><head><meta charset='utf-8'>",
        f"<title>{esc(title)}</title><style>{STYLE}</style></head><body>",
        f"<h1>{esc(title)}</h1>",
        f"<p>{esc(rc.summary(report))}</p>",
        f"<p>{esc(metadata_text(report))}</p>",
        *_html_verdict(report),
        "<h2>Findings</h2><ul>",
        *(f"<li>{esc(f)}</li>" for f in findings),
        "</ul>",
        "<h2>Accuracy over the whole campaign</h2>",
        *(_html_table(t) for t in rc.statistics_tables(report["overall"]["axes"])),
        f"<p class='note'>{esc(rc.reading_notes(report))}</p>",
        "<h2>Per set-point</h2>",
        _html_table(rc.setpoint_table(report)),
    ]
    if report.get("camera_settings"):
        parts += ["<h2>By camera setting</h2>", _html_table(camera_table(report))]
    parts.append("<h2>Plots</h2>")
    plots = camera_plots(report) + evidence_plots(report, rows)
    if not plots:
        parts.append(f"<p>{esc(NO_PLOTS)}</p>")
    if report.get("dynamic"):
        parts.append("<h2>Dynamic accuracy (motion profiles)</h2>")
        parts += [_html_table(t) for t in dynamic_tables(report)]
        plots = dynamic_plots(report) + plots
    for plot in plots:
        parts.append(
            f"<p><img alt='{esc(plot.title)}' "
            f"src='data:image/png;base64,{_png_b64(standalone(plot))}'></p>"
        )
    parts += _html_setpoint_details(report)
    parts.append(
        f"<p class='note'>Generated {esc(report['generated_at'])} by tofpose.</p></body></html>"
    )
    return "\n".join(parts)


def _png_b64(fig: Figure) -> str:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=90)  # a pyplot-free Figure: nothing to close
    return base64.b64encode(buf.getvalue()).decode()


def to_pdf(report: dict, rows: list[dict]) -> bytes:
    """The report as PDF (A4 landscape pages, see ``report_pdf``)."""
    return report_pdf.to_pdf(report, rows)
