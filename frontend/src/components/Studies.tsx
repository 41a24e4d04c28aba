// Accuracy studies (Monte-Carlo over the envelope, on Dask; docs/scaleout.md): submit a
// spec, follow progress and ETA, cancel, open the report.
import { useEffect, useState } from "preact/hooks";
import { api, type Study, type StudyCreate } from "../api/client";
import { fmtDuration } from "../format";

const EXAMPLE: StudyCreate = {
  name: "envelope", seed: 1, frames_per_cell: 8, chunk_frames: 4,
  grid: { range_m: [3, 6], attitude_deg: [20], physics: ["ideal", "lens blur"] },
};

export function Studies({ onError }: { onError: (m: string | null) => void }) {
  const [list, setList] = useState<Study[]>([]);
  const [text, setText] = useState(JSON.stringify(EXAMPLE, null, 2));
  const refresh = () => api<Study[]>("GET", "/api/studies").then(setList).catch((e) => onError(e.message));
  useEffect(() => {
    refresh();
    const t = window.setInterval(refresh, 1000);
    return () => window.clearInterval(t);
  }, []);
  const submit = async () => {
    let body: StudyCreate;
    try {
      body = JSON.parse(text) as StudyCreate;
    } catch (e) {
      onError(`study spec: not JSON (${(e as Error).message})`);
      return;
    }
    try {
      await api<Study>("POST", "/api/studies", body);
      onError(null);
      refresh();
    } catch (e) {
      onError((e as Error).message);
    }
  };
  const cancel = async (s: Study) => {
    try {
      await api<Study>("POST", `/api/studies/${s.id}/cancel`);
      onError(null);
      refresh();
    } catch (e) {
      onError((e as Error).message);
    }
  };
  return (
    <section class="card">
      <h2>Accuracy studies</h2>
      {list.length === 0 ? <p class="small">none yet</p> : (
        <table data-testid="studies">
          <thead><tr><th>id</th><th>name</th><th>status</th><th>frames</th><th>ETA</th><th>cluster</th><th /><th>report</th></tr></thead>
          <tbody>
            {list.map((s) => (
              <tr key={s.id} data-testid={`study-${s.id}`}>
                <td>{s.id}</td><td>{s.name}</td>
                <td data-testid={`study-status-${s.id}`}>{s.status}{s.error ? `: ${s.error}` : ""}</td>
                <td><progress max={s.frames_planned} value={s.frames_done} /> {s.frames_done} / {s.frames_planned} ({s.cells} cells)</td>
                <td>{s.status === "running" ? fmtDuration(s.eta_s) : "-"}</td>
                <td class="small">{s.cluster ?? "-"}</td>
                <td>{["queued", "running", "created"].includes(s.status) && (
                  <button data-testid={`study-cancel-${s.id}`} onClick={() => cancel(s)}>cancel</button>
                )}</td>
                <td>{s.reports.map((f) => (
                  <a key={f} data-testid={`study-report-${f}-${s.id}`} href={`/api/studies/${s.id}/report.${f}`} target="_blank" rel="noopener">{f} </a>
                ))}</td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
      <details>
        <summary>new study</summary>
        <p class="small">Grid axes: range_m, attitude_deg, offset_fraction, ambient_lux, physics (ideal, grey plate,
          lens blur, gains, all), catalog, preset (default, paper); every combination is a cell.</p>
        <textarea data-testid="study-spec" rows={10} cols={60} value={text}
          onInput={(e) => setText((e.target as HTMLTextAreaElement).value)} />
        <div><button data-testid="study-submit" onClick={submit}>submit study</button></div>
      </details>
    </section>
  );
}
