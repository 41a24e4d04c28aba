// Create a campaign from a generator: the server expands it into set-points and answers
// with the list and an estimated duration (a draft), which is shown before it is started.
import { useState } from "preact/hooks";
import { api, type Campaign } from "../api/client";

type Kind = "grid" | "range_sweep" | "stability" | "attitude_steps" | "calibration";

const nums = (s: string) => s.split(",").map((v) => v.trim()).filter((v) => v !== "").map(Number);

function generator(kind: Kind, p: Record<string, string>): Record<string, unknown> {
  const rail = p.rail ? Number(p.rail) : undefined;
  switch (kind) {
    case "grid":
      return { kind, yaw_deg: nums(p.yaw || "0"), pitch_deg: nums(p.pitch || "0"), roll_deg: nums(p.roll || "0"), rail_mm: nums(p.rail || "12000") };
    case "range_sweep":
      return { kind, rail_start_mm: Number(p.start || 9000), rail_stop_mm: Number(p.stop || 14000), points: Number(p.points || 6) };
    case "stability":
      return { kind, rail_mm: rail ?? 14303 };
    case "attitude_steps":
      return { kind, axis: p.axis || "roll", steps_deg: nums(p.steps || "0, 1, 2, 5, 0"), rail_mm: rail ?? 12000 };
    case "calibration":
      return { kind, rails_mm: nums(p.rails || "11000, 12500") };
  }
}

const PARAMS: Record<Kind, [string, string][]> = {
  grid: [["yaw", "yaw deg (list)"], ["pitch", "pitch deg (list)"], ["roll", "roll deg (list)"], ["rail", "rail mm (list)"]],
  range_sweep: [["start", "rail from mm"], ["stop", "rail to mm"], ["points", "points"]],
  stability: [["rail", "rail mm"]],
  attitude_steps: [["axis", "axis (yaw, pitch, roll)"], ["steps", "steps deg (list)"], ["rail", "rail mm"]],
  calibration: [["rails", "rails mm (list)"]],
};

export function NewCampaign({ onError }: { onError: (m: string | null) => void }) {
  const [name, setName] = useState("");
  const [kind, setKind] = useState<Kind>("grid");
  const [p, setP] = useState<Record<string, string>>({});
  const [frames, setFrames] = useState("20");
  const [draft, setDraft] = useState<Campaign | null>(null);
  const create = async () => {
    try {
      const body = { name, frames_per_point: Number(frames), generator: generator(kind, p) };
      setDraft(await api<Campaign>("POST", "/api/campaigns", body));
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    }
  };
  return (
    <section class="card">
      <h2>New campaign</h2>
      <div class="form">
        <label>name <input data-testid="new-name" value={name} onInput={(e) => setName((e.target as HTMLInputElement).value)} /></label>
        <label>generator <select data-testid="new-kind" value={kind} onChange={(e) => { setKind((e.target as HTMLSelectElement).value as Kind); setP({}); }}>
          {Object.keys(PARAMS).map((k) => <option key={k} value={k}>{k}</option>)}
        </select></label>
        {PARAMS[kind].map(([key, label]) => (
          <label key={key}>{label} <input data-testid={`new-${key}`} size={14} value={p[key] ?? ""}
            onInput={(e) => setP({ ...p, [key]: (e.target as HTMLInputElement).value })} /></label>
        ))}
        <label>frames per set-point <input data-testid="new-frames" size={5} value={frames} onInput={(e) => setFrames((e.target as HTMLInputElement).value)} /></label>
        <button data-testid="new-create" onClick={create}>create draft</button>
      </div>
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
