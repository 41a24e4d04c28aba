// Accuracy studies (Monte-Carlo over the envelope, on Dask; docs/scaleout.md): submit a
// spec, follow progress and ETA, cancel, open the report.
import { useState } from "preact/hooks";
import { api, unwrap, type Study, type StudyCreate } from "../api/client";
import { reported, useReportError } from "../errors";
import { fmtDuration } from "../format";
import { usePolling } from "../polling";

const EXAMPLE: StudyCreate = {
  name: "envelope", seed: 1, frames_per_cell: 8, chunk_frames: 4,
  grid: { range_m: [3, 6], attitude_deg: [20], physics: ["ideal", "lens blur"] },
};

export function Studies() {
  const report = useReportError();
  const studies = usePolling(() => unwrap(api.GET("/api/studies")), 1000);
  const list = studies.data ?? [];
  const [text, setText] = useState(JSON.stringify(EXAMPLE, null, 2));
  const submit = async () => {
    let body: StudyCreate;
    try {
      // what a person typed: the server validates it (a 422 names the field)
      body = JSON.parse(text) as StudyCreate;
    } catch (e) {
      report(`study spec: not JSON (${(e as Error).message})`);
      return;
    }
    if (await reported(report, () => unwrap(api.POST("/api/studies", { body })))) studies.refresh();
  };
  const cancel = async (s: Study) => {
    const path = { study_id: s.id };
    if (await reported(report, () => unwrap(api.POST("/api/studies/{study_id}/cancel", { params: { path } })))) studies.refresh();
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
