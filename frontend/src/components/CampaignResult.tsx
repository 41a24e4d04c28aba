// A finished campaign's key statistics and pass/fail per requirement (from its JSON
// report), a dynamic campaign's latency and rate errors, with the report's plots (its
// HTML page) below.
import { api, unwrap } from "../api/client";
import { cameraText } from "../campaignForm";
import { usePolling } from "../polling";

type AxisStats = { n: number; bias: number; std: number; rms: number; max_abs: number;
  predicted_sigma: number; requirement: number; passed: boolean | null };
// The report's JSON is not described by the OpenAPI schema (its answer is `unknown`):
// these types are what the server writes (backend/services/reports/reports.py), checked for shape by isReport.
// The dynamic section (null for a static campaign): the latency pooled over the set-points
// and, per dynamic set-point (by index), frames in motion and the rate's error.
type Latency = { delay_s: number; sigma_s: number; n_setpoints: number };
type DynamicSetpoint = { n_in_motion: number; lost_in_motion_share?: number | null;
  rate?: { peak_reference_deg_s: number | null; rms_error_in_motion_deg_s: number | null;
    rms_error_share_of_peak: number | null };
  latency?: { delay_s?: number; sigma_s?: number; why_none?: string } };
type Dynamic = { latency: Latency | null; setpoints: Record<string, DynamicSetpoint> };
// The campaign's metadata (who, what target, which camera) and, when it varied the camera,
// the statistics per camera setting (backend/services/reports/report_camera.py).
type CampaignMeta = { operator?: string; target_name?: string; camera_model?: string; camera_serial?: string;
  camera_firmware?: string; notes?: string };
type CameraGroup = { setting: Record<string, number>; n_frames: number; n_ok: number; success_rate: number;
  range_error_mean_mm: number | null; range_error_std_mm: number | null; passed: boolean | null };
type Report = { n_frames: number; n_ok: number; success_rate: number; reference: string;
  overall: { passed: boolean | null; axes: Record<string, AxisStats> }; findings: string[];
  dynamic?: Dynamic | null; campaign?: CampaignMeta; camera_settings?: CameraGroup[] | null };

/** Whether an answer has the report's top-level shape (else the page says it is not one). */
export function isReport(x: unknown): x is Report {
  const r = x as Partial<Report> | null;
  return typeof r === "object" && r !== null && typeof r.n_frames === "number" && typeof r.overall?.axes === "object"
    && Array.isArray(r.findings);
}

async function loadReport(id: number): Promise<Report> {
  const data = await unwrap(api.GET("/api/campaigns/{campaign_id}/report.{fmt}", { params: { path: { campaign_id: id, fmt: "json" } } }));
  if (!isReport(data)) throw new Error(`campaign ${id}: the report is not the JSON report this page reads`);
  return data;
}

const fmt = (v: number | null | undefined, d = 3) => (v === null || v === undefined || Number.isNaN(v) ? "-" : v.toFixed(d));
const pct = (v: number | null | undefined) => (v === null || v === undefined ? "-" : `${(100 * v).toFixed(1)} %`);
const verdict = (p: boolean | null) => (p === null ? "n/a" : p ? "pass" : "FAIL");

export function CampaignResult({ id }: { id: number }) {
  const rep = usePolling(() => loadReport(id), null, { deps: [id] }).data;
  if (!rep) return <p class="small">loading the report…</p>;
  return (
    <div class="result" data-testid={`result-${id}`}>
      {rep.campaign && <MetadataLine id={id} c={rep.campaign} />}
      <p>
        <strong data-testid={`verdict-${id}`} class={rep.overall.passed === false ? "error" : ""}>
          {verdict(rep.overall.passed)}
        </strong>{" "}
        against the {rep.reference} reference; {rep.n_ok} of {rep.n_frames} frames with a pose
        ({(100 * rep.success_rate).toFixed(1)} %)
      </p>
      <table class="small">
        <thead><tr><th>axis</th><th>bias</th><th>std</th><th>RMS</th><th>max |error|</th>
          <th>predicted 1-sigma</th><th>requirement</th><th /></tr></thead>
        <tbody>
          {Object.entries(rep.overall.axes).map(([axis, s]) => {
            const unit = axis.endsWith("_mm") ? "mm" : "deg";
            return (
              <tr key={axis}>
                <th>{axis.replace(/_(mm|deg)$/, "")} ({unit})</th>
                <td>{fmt(s.bias)}</td><td>{fmt(s.std)}</td><td>{fmt(s.rms)}</td><td>{fmt(s.max_abs)}</td>
                <td>{fmt(s.predicted_sigma)}</td><td>{fmt(s.requirement, 2)}</td>
                <td data-testid={`pass-${id}-${axis}`}>{verdict(s.passed)}</td>
              </tr>
            );
          })}
        </tbody>
      </table>
      {rep.camera_settings && <CameraSummary id={id} groups={rep.camera_settings} />}
      {rep.dynamic && <DynamicSummary id={id} dyn={rep.dynamic} />}
      {rep.findings.length > 0 && <ul class="small">{rep.findings.map((f) => <li key={f}>{f}</li>)}</ul>}
      <iframe title={`campaign ${id} report`} class="report" src={`/api/campaigns/${id}/report.html?inline=true`} />
    </div>
  );
}

const given = (v: string | undefined) => (v ? v : "not given");

function MetadataLine({ id, c }: { id: number; c: CampaignMeta }) {
  return (
    <p class="small" data-testid={`metadata-${id}`}>
      operator <strong>{given(c.operator)}</strong>; target <strong>{given(c.target_name)}</strong>; camera{" "}
      {given(c.camera_model)}, serial <strong>{given(c.camera_serial)}</strong>, firmware {given(c.camera_firmware)}
      {c.notes ? <>; notes: {c.notes}</> : null}
    </p>
  );
}

function CameraSummary({ id, groups }: { id: number; groups: CameraGroup[] }) {
  return (
    <table class="small" style={{ marginTop: "0.8em" }} data-testid={`camera-settings-${id}`}>
      <caption style={{ textAlign: "left", fontWeight: "bold" }}>by camera setting</caption>
      <thead><tr><th>camera setting</th><th>frames with a pose</th><th>range error mean (mm)</th>
        <th>range error 1-sigma (mm)</th><th /></tr></thead>
      <tbody>
        {groups.map((g) => (
          <tr key={cameraText(g.setting)}>
            <th>{cameraText(g.setting)}</th><td>{g.n_ok} of {g.n_frames} ({pct(g.success_rate)})</td>
            <td>{fmt(g.range_error_mean_mm, 2)}</td><td>{fmt(g.range_error_std_mm, 2)}</td><td>{verdict(g.passed)}</td>
          </tr>
        ))}
      </tbody>
    </table>
  );
}

function DynamicSummary({ id, dyn }: { id: number; dyn: Dynamic }) {
  const lat = dyn.latency;
  const why = Object.values(dyn.setpoints).find((sp) => sp.latency?.why_none)?.latency?.why_none;
  return (
    <div data-testid={`dynamic-${id}`}>
      <p class="small" title="a frame's pose is the attitude the reference had that long before its time stamp">
        <strong>Dynamic</strong>: latency <strong data-testid={`latency-${id}`}>
          {lat ? `${fmt(1000 * lat.delay_s, 1)} ± ${fmt(1000 * lat.sigma_s, 1)} ms` : "-"}
        </strong>
        {lat ? ` (pooled over ${lat.n_setpoints} set-point${lat.n_setpoints === 1 ? "" : "s"})` : why ? ` (no fit: ${why})` : " (no fit)"}
      </p>
      <table class="small">
        <thead><tr><th>set-point</th><th>frames in motion</th><th>lost in motion</th><th>peak rate (deg/s)</th>
          <th>rate RMS error (deg/s)</th><th>of peak</th></tr></thead>
        <tbody>
          {Object.entries(dyn.setpoints).map(([index, sp]) => (
            <tr key={index} data-testid={`dynamic-${id}-${index}`}>
              <th>{index}</th><td>{sp.n_in_motion}</td><td>{pct(sp.lost_in_motion_share)}</td>
              <td>{fmt(sp.rate?.peak_reference_deg_s, 2)}</td><td>{fmt(sp.rate?.rms_error_in_motion_deg_s)}</td>
              <td>{pct(sp.rate?.rms_error_share_of_peak)}</td>
            </tr>
          ))}
        </tbody>
      </table>
    </div>
  );
}
