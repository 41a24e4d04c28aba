// Record the live stream on demand (POST /api/recordings): a name, an optional duration,
// record / stop, each running recording's time, frames and size as the server counts
// them, the free space left on the server's data disk (below its floor a recording is
// refused, and a running one stops) and every recording with its HDF5 and MCAP downloads.
import { useState } from "preact/hooks";
import { api, unwrap, type Schemas } from "../api/client";
import { reported, useReportError } from "../errors";
import { fmtDuration } from "../format";
import { usePolling } from "../polling";

type Recording = Schemas["RecordingPublic"];

const mb = (bytes: number) => (bytes / 1e6).toFixed(1);

/** "12 s / 30 s" of a running recording (its duration, when it has one). */
function elapsedText(r: Recording): string {
  return `${fmtDuration(r.elapsed_s)}${r.duration_s ? ` / ${fmtDuration(r.duration_s)}` : ""}`;
}

/** What the list says of a recording's state: "recording", or why it stopped. */
function stateText(r: Recording): string {
  if (r.state === "recording") return "recording";
  return r.stop_reason === "requested" ? "stopped" : `stopped: ${r.stop_reason}`;
}

export function Recorder() {
  const report = useReportError();
  const polled = usePolling(() => unwrap(api.GET("/api/recordings")), 1000);
  const [name, setName] = useState("");
  const [duration, setDuration] = useState("");
  const [fieldError, setFieldError] = useState<string | null>(null);
  const [pending, setPending] = useState<string | null>(null);
  const data = polled.data;
  if (!data) return <section class="card"><h2>Record</h2><p>loading</p></section>;
  const running = data.recordings.filter((r) => r.state === "recording");
  const lowDisk = data.free_mb < data.min_free_mb;
  const full = running.length >= data.max_active;

  const command = async (key: string, send: () => Promise<unknown>) => {
    if (pending !== null) return; // one command at a time: a double click sends one
    setPending(key);
    try {
      if ((await reported(report, send)) !== undefined) polled.refresh();
    } finally {
      setPending(null);
    }
  };
  const start = () => {
    const n = name.trim();
    if (!n) return setFieldError("give the recording a name");
    let duration_s: number | null = null;
    if (duration.trim() !== "") {
      duration_s = Number(duration);
      if (!Number.isFinite(duration_s) || duration_s <= 0)
        return setFieldError("duration: seconds > 0, or empty to record until stopped");
    }
    setFieldError(null);
    return command("start", async () => {
      const r = await unwrap(api.POST("/api/recordings", { body: { name: n, duration_s } }));
      setName("");
      return r;
    });
  };
  const stop = (id: number) =>
    command(`stop-${id}`, () => unwrap(api.POST("/api/recordings/{recording_id}/stop", { params: { path: { recording_id: id } } })));

  return (
    <section class="card" data-testid="recorder">
      <h2>Record</h2>
      <div class="form">
        <label>name <input data-testid="rec-name" size={16} value={name} placeholder="what it is for"
          onInput={(e) => setName((e.target as HTMLInputElement).value)}
          onKeyDown={(e) => { if (e.key === "Enter") start(); }} /></label>
        <label>duration <input data-testid="rec-duration" size={6} value={duration} placeholder="until stop"
          onInput={(e) => setDuration((e.target as HTMLInputElement).value)} /> s</label>
        <button data-testid="rec-start" disabled={pending !== null || lowDisk || full} onClick={start}
          title={full ? `at most ${data.max_active} recordings at once` : "record the live stream to HDF5"}>● record</button>
      </div>
      {fieldError && <span class="field-error" data-testid="rec-field-error">{fieldError}</span>}
      {running.map((r) => (
        <p key={r.id} data-testid={`rec-live-${r.id}`}>
          <span class="badge warn">● REC</span> {r.name}: <span data-testid={`rec-elapsed-${r.id}`}>{elapsedText(r)}</span>,{" "}
          <span data-testid={`rec-frames-${r.id}`}>{r.frames}</span> frames,{" "}
          <span data-testid={`rec-size-${r.id}`}>{mb(r.size_bytes)}</span> MB{" "}
          <button data-testid={`rec-stop-${r.id}`} disabled={pending !== null} onClick={() => stop(r.id)}>stop</button>
        </p>
      ))}
      <p class={`small${lowDisk ? " error" : ""}`} data-testid="rec-disk">
        {(data.free_mb / 1000).toFixed(1)} GB free on the server's data disk
        {lowDisk ? `: below the floor of ${data.min_free_mb} MB, recording is refused` : ` (recordings stop below ${data.min_free_mb} MB)`};
        recordings take {data.used_mb.toFixed(0)} MB
      </p>
      {data.recordings.length > 0 && (
        <table class="small" data-testid="recordings">
          <thead><tr><th>id</th><th>name</th><th>started</th><th>time</th><th>frames</th><th>MB</th><th>state</th><th>files</th></tr></thead>
          <tbody>
            {data.recordings.map((r) => (
              <tr key={r.id} data-testid={`recording-${r.id}`}>
                <td>{r.id}</td><td>{r.name}</td><td>{new Date(r.started_utc).toLocaleString()}</td>
                <td>{fmtDuration(r.elapsed_s)}</td><td>{r.frames}</td><td>{mb(r.size_bytes)}</td>
                <td data-testid={`rec-state-${r.id}`} title={r.stop_detail}>{stateText(r)}</td>
                <td>{r.state === "stopped" && (["h5", "mcap"] as const).map((f) => (
                  <a key={f} data-testid={`rec-${f}-${r.id}`} download
                    title={f === "h5" ? "HDF5 (tofpose.recording)" : "MCAP: Foxglove, Rerun (made on the first request)"}
                    href={`/api/recordings/${r.id}/recording.${f}`}>{f} </a>
                ))}</td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
    </section>
  );
}
