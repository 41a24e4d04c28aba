// Create a campaign from a generator: the server expands it into set-points and answers
// with the list and an estimated duration (a draft), which is shown before it is started.
import { useEffect, useRef, useState } from "preact/hooks";
import { api, type Campaign } from "../api/client";
import { parseNumber, parseNumberList } from "../setpoint";

type Kind = "grid" | "range_sweep" | "stability" | "attitude_steps" | "calibration" | "profile";
type Shape = "sine" | "ramp";

// Each parameter: its label and the default used when the field is left empty (shown as
// the field's placeholder, so what is sent is what the page shows). `optional`: left empty,
// the field is not sent (the server's default, which the placeholder names); `choices`: a
// select; `profile`: a field of the generator's motion profile (body.generator.profile).
type Param = { key: string; label: string; fallback: string; list?: boolean; text?: boolean;
  optional?: boolean; choices?: string[]; profile?: boolean };

/** The generator body, or the first field that is not what it says (nothing is sent). */
function generator(kind: Kind, shape: Shape, p: Record<string, string>): { body: Record<string, unknown> } | { error: string } {
  const out: Record<string, unknown> = { kind };
  const profile: Record<string, unknown> = { kind: shape };
  if (kind === "profile") out.profile = profile;
  for (const param of params(kind, shape)) {
    const target = param.profile ? profile : out;
    const typed = (p[param.key] ?? "").trim();
    if (param.optional && typed === "") continue;
    const raw = typed || param.fallback;
    if (param.text || param.choices) {
      target[param.key] = raw;
      continue;
    }
    const parsed = param.list ? parseNumberList(raw) : parseNumber(raw);
    if ("error" in parsed) return { error: `${param.label}: ${parsed.error}` };
    target[param.key] = "values" in parsed ? parsed.values : parsed.value;
  }
  return { body: out };
}

// A dynamic campaign: the profile (its axis, sine or ramp and that shape's fields), the
// rests around it and the start points, every combination of the lists (as a grid).
const SHAPE_PARAMS: Record<Shape, Param[]> = {
  sine: [
    { key: "amplitude_deg", label: "amplitude deg", fallback: "5", profile: true },
    { key: "period_s", label: "period s", fallback: "4", profile: true },
    { key: "cycles", label: "cycles", fallback: "1", profile: true },
  ],
  ramp: [
    { key: "rate_deg_s", label: "rate deg/s", fallback: "10", profile: true },
    { key: "hold_s", label: "hold s", fallback: "2", profile: true },
    { key: "accel_deg_s2", label: "accel deg/s² (optional)", fallback: "axis limit", optional: true, profile: true },
  ],
};

function params(kind: Kind, shape: Shape): Param[] {
  if (kind !== "profile") return PARAMS[kind];
  const [axis, ...rest] = PARAMS.profile;
  return [axis, ...SHAPE_PARAMS[shape], ...rest];
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
  profile: [
    { key: "axis", label: "profile axis", fallback: "yaw", choices: ["yaw", "pitch", "roll"], profile: true },
    { key: "rest_s", label: "rest s (before, after)", fallback: "2" },
    { key: "yaw_deg", label: "start yaw deg (list)", fallback: "0", list: true },
    { key: "pitch_deg", label: "start pitch deg (list)", fallback: "0", list: true },
    { key: "roll_deg", label: "start roll deg (list)", fallback: "0", list: true },
    { key: "rail_mm", label: "rail mm (list)", fallback: "12000", list: true },
  ],
};

/** A set-point's motion profile in a few words ("sine yaw 2 deg / 2 s x1, rests 0.5 s"). */
function profileText(pr: Record<string, unknown>): string {
  const shape = pr.kind === "sine"
    ? `${pr.amplitude_deg} deg / ${pr.period_s} s x${pr.cycles}`
    : `${pr.rate_deg_s} deg/s for ${pr.hold_s} s${pr.accel_deg_s2 != null ? ` at ${pr.accel_deg_s2} deg/s²` : ""}`;
  return `${pr.kind} ${pr.axis} ${shape}, rests ${pr.rest_s} s`;
}

const KIND_LABEL: Partial<Record<Kind, string>> = { profile: "dynamic (motion profile)" };

export function NewCampaign({ onError, calibrationRequest = 0 }: { onError: (m: string | null) => void; calibrationRequest?: number }) {
  const [name, setName] = useState("");
  const [kind, setKind] = useState<Kind>("grid");
  const [shape, setShape] = useState<Shape>("sine");
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
    const gen = generator(kind, shape, p);
    // a dynamic campaign keeps every frame of its rests and profile: no frame count
    const nFrames = kind === "profile" ? null : parseNumber(frames);
    const problem = "error" in gen ? gen.error : nFrames && "error" in nFrames ? `frames per set-point: ${nFrames.error}` : null;
    setFormError(problem);
    if (problem !== null || "error" in gen || (nFrames && "error" in nFrames) || busy) return;
    setBusy(true);
    try {
      const body = { name, ...(nFrames ? { frames_per_point: nFrames.value } : {}), generator: gen.body, record_raw: recordRaw };
      setDraft(await api<Campaign>("POST", "/api/campaigns", body));
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    } finally {
      setBusy(false);
    }
  };
  const dynamic = (draft?.setpoints ?? []).some((sp) => sp.profile);
  return (
    <section class="card" ref={form} data-testid="new-campaign">
      <h2>New campaign</h2>
      <div class="form">
        <label>name <input data-testid="new-name" value={name} onInput={(e) => setName((e.target as HTMLInputElement).value)} /></label>
        <label>generator <select data-testid="new-kind" value={kind} onChange={(e) => { setKind((e.target as HTMLSelectElement).value as Kind); setP({}); }}>
          {(Object.keys(PARAMS) as Kind[]).map((k) => <option key={k} value={k}>{KIND_LABEL[k] ?? k}</option>)}
        </select></label>
        {kind === "profile" && (
          <label>profile <select data-testid="new-profile-kind" value={shape} onChange={(e) => setShape((e.target as HTMLSelectElement).value as Shape)}>
            <option value="sine">sine</option><option value="ramp">ramp</option>
          </select></label>
        )}
        {params(kind, shape).map(({ key, label, fallback, choices, optional }) => choices ? (
          <label key={key}>{label} <select data-testid={`new-${key}`} value={p[key] || fallback}
            onChange={(e) => setP({ ...p, [key]: (e.target as HTMLSelectElement).value })}>
            {choices.map((c) => <option key={c} value={c}>{c}</option>)}
          </select></label>
        ) : (
          <label key={key}>{label} <input data-testid={`new-${key}`} size={14} value={p[key] ?? ""}
            placeholder={fallback} title={optional ? `empty: not sent (${fallback})` : `empty: ${fallback}`}
            onInput={(e) => setP({ ...p, [key]: (e.target as HTMLInputElement).value })} /></label>
        ))}
        {kind === "profile" ? (
          <span class="small" data-testid="new-frames-na" title="every frame of the rests and the profile is kept">frames per set-point: does not apply</span>
        ) : (
          <label>frames per set-point <input data-testid="new-frames" size={5} value={frames} onInput={(e) => setFrames((e.target as HTMLInputElement).value)} /></label>
        )}
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
            <thead><tr><th>#</th><th>yaw deg</th><th>pitch deg</th><th>roll deg</th><th>rail mm</th>{dynamic && <th>profile</th>}</tr></thead>
            <tbody>
              {(draft.setpoints ?? []).slice(0, 30).map((sp) => (
                <tr key={sp.index}><td>{sp.index}</td><td>{sp.yaw_deg ?? "-"}</td><td>{sp.pitch_deg ?? "-"}</td><td>{sp.roll_deg ?? "-"}</td><td>{sp.rail_mm ?? "-"}</td>
                  {dynamic && <td data-testid={`draft-profile-${sp.index}`}>{sp.profile ? profileText(sp.profile) : "-"}</td>}</tr>
              ))}
            </tbody>
          </table>
          {(draft.setpoints?.length ?? 0) > 30 && <p class="small">... {draft.n_setpoints - 30} more</p>}
        </div>
      )}
    </section>
  );
}
