// Create a campaign from a generator: the server expands it into set-points and answers
// with the list and an estimated duration (a draft), which is shown before it is started.
import { useEffect, useRef, useState } from "preact/hooks";
import { api, type Campaign } from "../api/client";
import { parseNumber, parseNumberList } from "../setpoint";

type Kind = "grid" | "range_sweep" | "stability" | "attitude_steps" | "calibration";

// Each parameter: its label and the default used when the field is left empty (shown as
// the field's placeholder, so what is sent is what the page shows).
type Param = { key: string; label: string; fallback: string; list?: boolean; text?: boolean };

/** The generator body, or the first field that is not what it says (nothing is sent). */
function generator(kind: Kind, p: Record<string, string>): { body: Record<string, unknown> } | { error: string } {
  const out: Record<string, unknown> = { kind };
  for (const param of PARAMS[kind]) {
    const raw = (p[param.key] ?? "").trim() || param.fallback;
    if (param.text) {
      out[param.key] = raw;
      continue;
    }
    const parsed = param.list ? parseNumberList(raw) : parseNumber(raw);
    if ("error" in parsed) return { error: `${param.label}: ${parsed.error}` };
    out[param.key] = "values" in parsed ? parsed.values : parsed.value;
  }
  return { body: out };
}

const PARAMS: Record<Kind, Param[]> = {
  grid: [
    { key: "yaw_deg", label: "yaw deg (list)", fallback: "0", list: true },
    { key: "pitch_deg", label: "pitch deg (list)", fallback: "0", list: true },
    { key: "roll_deg", label: "roll deg (list)", fallback: "0", list: true },
    { key: "rail_mm", label: "rail mm (list)", fallback: "12000", list: true },
  ],
  range_sweep: [
    { key: "rail_start_mm", label: "rail from mm", fallback: "9000" },
    { key: "rail_stop_mm", label: "rail to mm", fallback: "14000" },
    { key: "points", label: "points", fallback: "6" },
  ],
  stability: [{ key: "rail_mm", label: "rail mm", fallback: "14303" }],
  attitude_steps: [
    { key: "axis", label: "axis (yaw, pitch, roll)", fallback: "roll", text: true },
    { key: "steps_deg", label: "steps deg (list)", fallback: "0, 1, 2, 5, 0", list: true },
    { key: "rail_mm", label: "rail mm", fallback: "12000" },
  ],
  calibration: [{ key: "rails_mm", label: "rails mm (list)", fallback: "11000, 12500", list: true }],
};

export function NewCampaign({ onError, calibrationRequest = 0 }: { onError: (m: string | null) => void; calibrationRequest?: number }) {
  const [name, setName] = useState("");
  const [kind, setKind] = useState<Kind>("grid");
  const [p, setP] = useState<Record<string, string>>({});
  const [frames, setFrames] = useState("20");
  const [recordRaw, setRecordRaw] = useState(false);
  const [draft, setDraft] = useState<Campaign | null>(null);
  const [formError, setFormError] = useState<string | null>(null);
  const form = useRef<HTMLElement>(null);
  useEffect(() => {
    if (calibrationRequest === 0) return;
    setKind("calibration");
    setP({});
    if (!name) setName("bench-calibration");
    form.current?.scrollIntoView({ behavior: "smooth" });
  }, [calibrationRequest]);
  const [busy, setBusy] = useState(false);
  const create = async () => {
    const gen = generator(kind, p);
    const nFrames = parseNumber(frames);
    const problem = "error" in gen ? gen.error : "error" in nFrames ? `frames per set-point: ${nFrames.error}` : null;
    setFormError(problem);
    if (problem !== null || "error" in gen || "error" in nFrames || busy) return;
    setBusy(true);
    try {
      const body = { name, frames_per_point: nFrames.value, generator: gen.body, record_raw: recordRaw };
      setDraft(await api<Campaign>("POST", "/api/campaigns", body));
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    } finally {
      setBusy(false);
    }
  };
  return (
    <section class="card" ref={form} data-testid="new-campaign">
      <h2>New campaign</h2>
      <div class="form">
        <label>name <input data-testid="new-name" value={name} onInput={(e) => setName((e.target as HTMLInputElement).value)} /></label>
        <label>generator <select data-testid="new-kind" value={kind} onChange={(e) => { setKind((e.target as HTMLSelectElement).value as Kind); setP({}); }}>
          {Object.keys(PARAMS).map((k) => <option key={k} value={k}>{k}</option>)}
        </select></label>
        {PARAMS[kind].map(({ key, label, fallback }) => (
          <label key={key}>{label} <input data-testid={`new-${key}`} size={14} value={p[key] ?? ""}
            placeholder={fallback} title={`empty: ${fallback}`}
            onInput={(e) => setP({ ...p, [key]: (e.target as HTMLInputElement).value })} /></label>
        ))}
        <label>frames per set-point <input data-testid="new-frames" size={5} value={frames} onInput={(e) => setFrames((e.target as HTMLInputElement).value)} /></label>
        <label title="every measured frame pair in a recording (HDF5, also downloadable as MCAP for Foxglove / Rerun)">
          <input type="checkbox" data-testid="new-record-raw" checked={recordRaw}
            onChange={(e) => setRecordRaw((e.target as HTMLInputElement).checked)} /> keep raw frames</label>
        <button data-testid="new-create" onClick={create} disabled={busy}>create draft</button>
      </div>
      {formError && <p class="field-error" role="alert" data-testid="new-error">{formError}</p>}
      {draft && (
        <div data-testid="draft">
          <p class="small">Draft {draft.id} "{draft.name}": {draft.n_setpoints} set-points, estimated
            {" "}{Math.round(draft.estimated_duration_s)} s. Start it in the campaign list.</p>
          <table class="small">
            <thead><tr><th>#</th><th>yaw deg</th><th>pitch deg</th><th>roll deg</th><th>rail mm</th></tr></thead>
            <tbody>
              {(draft.setpoints ?? []).slice(0, 30).map((sp) => (
                <tr key={sp.index}><td>{sp.index}</td><td>{sp.yaw_deg ?? "-"}</td><td>{sp.pitch_deg ?? "-"}</td><td>{sp.roll_deg ?? "-"}</td><td>{sp.rail_mm ?? "-"}</td></tr>
              ))}
            </tbody>
          </table>
          {(draft.setpoints?.length ?? 0) > 30 && <p class="small">... {draft.n_setpoints - 30} more</p>}
        </div>
      )}
    </section>
  );
}
