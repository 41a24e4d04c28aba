// Campaigns: status and progress, start / pause / resume / cancel, report downloads, and
// for a finished one its statistics and pass/fail (CampaignResult).
import { useState } from "preact/hooks";
import { api, unwrap, type Campaign } from "../api/client";
import { cameraText } from "../campaignForm";
import { commandsIn, type CampaignCommand } from "../campaignStates";
import { reported, useReportError } from "../errors";
import { fmtDuration } from "../format";
import { usePolling } from "../polling";
import { CampaignResult } from "./CampaignResult";

type Action = CampaignCommand;

/** One action's request (each its own path in the schema). */
function request(action: Action, id: number) {
  const path = { params: { path: { campaign_id: id } } };
  switch (action) {
    case "start": return api.POST("/api/campaigns/{campaign_id}/start", { ...path, body: { queue: true } });
    case "pause": return api.POST("/api/campaigns/{campaign_id}/pause", path);
    case "resume": return api.POST("/api/campaigns/{campaign_id}/resume", path);
    case "cancel": return api.POST("/api/campaigns/{campaign_id}/cancel", path);
  }
}

export function Campaigns() {
  const report = useReportError();
  const campaigns = usePolling(() => unwrap(api.GET("/api/campaigns")), 1000);
  // the commands each state allows: the server's table, loaded once
  const states = usePolling(() => unwrap(api.GET("/api/campaigns/states")), null);
  const list = campaigns.data ?? [];
  const [open, setOpen] = useState<number | null>(null);
  // campaigns that wait for a person since the server (re)started: nothing runs them alone
  const waiting = list.filter((c) => c.status === "interrupted"
    || (c.status === "paused" && (c.status_reason ?? "").startsWith("held at server start")));
  const act = async (c: Campaign, action: Action) => {
    if ((await reported(report, () => unwrap(request(action, c.id)))) !== undefined) campaigns.refresh();
  };
  return (
    <section class="card">
      <h2>Campaigns</h2>
      {waiting.length > 0 && (
        <p class="small warn" data-testid="campaigns-held">
          {waiting.length} campaign{waiting.length > 1 ? "s" : ""} ({waiting.map((c) => c.id).join(", ")}) wait
          since the server stopped: nothing moves the turntable after a restart until a person resumes them.
        </p>
      )}
      {list.length === 0 ? <p class="small">none yet (POST /api/campaigns; see docs/campaigns.md)</p> : (
        <table data-testid="campaigns">
          <thead><tr><th>id</th><th>name</th><th>status</th><th>progress</th><th>ETA</th><th /><th>report</th></tr></thead>
          <tbody>
            {list.map((c) => (
              <tr key={c.id} data-testid={`campaign-${c.id}`}>
                <td>{c.id}</td><td>{c.name}{c.operator ? <span class="small" data-testid={`operator-${c.id}`}> ({c.operator})</span> : null}</td>
                <td data-testid={`status-${c.id}`}>{c.status}{c.status_reason ? `: ${c.status_reason}` : ""}</td>
                <td>
                  <progress max={c.n_setpoints} value={c.n_done} /> {c.n_done} / {c.n_setpoints}
                  {c.progress && c.status === "running" ? ` (set-point ${c.progress.setpoint_index}: ${c.progress.frames_collected}/${c.progress.frames_per_point} frames${c.progress.camera ? `, ${cameraText(c.progress.camera)}` : ""})` : ""}
                </td>
                <td>{fmtDuration(c.status === "running" ? c.progress?.eta_s : c.estimated_duration_s)}</td>
                <td>{commandsIn(states.data, c.status).map((a) => (
                  <button key={a} data-testid={`${a}-${c.id}`} onClick={() => act(c, a)}>{a}</button>
                ))}</td>
                <td>{(["html", "pdf", "csv", "json"] as const).map((f) => (
                  <a key={f} data-testid={`report-${f}-${c.id}`} href={`/api/campaigns/${c.id}/report.${f}`}>{f} </a>
                ))}
                {c.record_raw && c.status !== "running" && c.status !== "draft" && (["h5", "mcap"] as const).map((f) => (
                  <a key={f} data-testid={`recording-${f}-${c.id}`} title={`raw frames (${f === "h5" ? "HDF5" : "MCAP: Foxglove, Rerun"})`}
                    href={`/api/campaigns/${c.id}/recording.${f}`}>frames.{f} </a>
                ))}
                {c.status === "done" && (
                  <button data-testid={`results-${c.id}`} aria-expanded={open === c.id}
                    onClick={() => setOpen(open === c.id ? null : c.id)}>results</button>
                )}</td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
      {open !== null && <CampaignResult id={open} />}
    </section>
  );
}
