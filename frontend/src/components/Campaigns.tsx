// Campaigns: status and progress, start / pause / resume / cancel, report downloads, and
// for a finished one its statistics and pass/fail (CampaignResult).
import { useEffect, useState } from "preact/hooks";
import { api, type Campaign } from "../api/client";
import { fmtDuration } from "../format";
import { CampaignResult } from "./CampaignResult";

const ACTIONS: Record<string, string[]> = {
  draft: ["start", "cancel"], queued: ["pause", "cancel"], running: ["pause", "cancel"],
  paused: ["resume", "cancel"], interrupted: ["resume", "cancel"],
};

export function Campaigns({ onError }: { onError: (m: string | null) => void }) {
  const [list, setList] = useState<Campaign[]>([]);
  const [open, setOpen] = useState<number | null>(null);
  const refresh = () => api<Campaign[]>("GET", "/api/campaigns").then(setList).catch((e) => onError(e.message));
  useEffect(() => {
    refresh();
    const t = window.setInterval(refresh, 1000);
    return () => window.clearInterval(t);
  }, []);
  const act = async (c: Campaign, action: string) => {
    try {
      const body = action === "start" ? { queue: true } : undefined;
      await api("POST", `/api/campaigns/${c.id}/${action}`, body);
      onError(null);
      refresh();
    } catch (e) {
      onError((e as Error).message);
    }
  };
  return (
    <section class="card">
      <h2>Campaigns</h2>
      {list.length === 0 ? <p class="small">none yet (POST /api/campaigns; see docs/campaigns.md)</p> : (
        <table data-testid="campaigns">
          <thead><tr><th>id</th><th>name</th><th>status</th><th>progress</th><th>ETA</th><th /><th>report</th></tr></thead>
          <tbody>
            {list.map((c) => (
              <tr key={c.id} data-testid={`campaign-${c.id}`}>
                <td>{c.id}</td><td>{c.name}</td>
                <td data-testid={`status-${c.id}`}>{c.status}{c.status_reason ? `: ${c.status_reason}` : ""}</td>
                <td>
                  <progress max={c.n_setpoints} value={c.n_done} /> {c.n_done} / {c.n_setpoints}
                  {c.progress && c.status === "running" ? ` (set-point ${c.progress.setpoint_index}: ${c.progress.frames_collected}/${c.progress.frames_per_point} frames)` : ""}
                </td>
                <td>{fmtDuration(c.status === "running" ? c.progress?.eta_s : c.estimated_duration_s)}</td>
                <td>{(ACTIONS[c.status] ?? []).map((a) => (
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
      {open !== null && <CampaignResult id={open} onError={onError} />}
    </section>
  );
}
