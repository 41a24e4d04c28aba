// A finished campaign's key statistics and pass/fail per requirement (from its JSON
// report), with the report's plots (its HTML page) below.
import { useEffect, useState } from "preact/hooks";
import { api } from "../api/client";

type AxisStats = { n: number; bias: number; std: number; rms: number; max_abs: number;
  predicted_sigma: number; requirement: number; passed: boolean | null };
type Report = { n_frames: number; n_ok: number; success_rate: number; reference: string;
  overall: { passed: boolean | null; axes: Record<string, AxisStats> }; findings: string[] };

const fmt = (v: number | null | undefined, d = 3) => (v === null || v === undefined || Number.isNaN(v) ? "-" : v.toFixed(d));
const verdict = (p: boolean | null) => (p === null ? "n/a" : p ? "pass" : "FAIL");

export function CampaignResult({ id, onError }: { id: number; onError: (m: string | null) => void }) {
  const [rep, setRep] = useState<Report | null>(null);
  useEffect(() => {
    api<Report>("GET", `/api/campaigns/${id}/report.json`).then(setRep).catch((e) => onError(e.message));
  }, [id]);
  if (!rep) return <p class="small">loading the report…</p>;
  return (
    <div class="result" data-testid={`result-${id}`}>
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
      {rep.findings.length > 0 && <ul class="small">{rep.findings.map((f) => <li key={f}>{f}</li>)}</ul>}
      <iframe title={`campaign ${id} report`} class="report" src={`/api/campaigns/${id}/report.html?inline=true`} />
    </div>
  );
}
