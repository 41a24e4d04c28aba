// Accuracy studies (Monte-Carlo over the envelope, on Dask; docs/scaleout.md): build a spec
// in a form (grid axes as lists or ranges, physics, presets, frames per cell, requirements)
// or as JSON (the same spec; either view's edits show in the other), submit it, follow
// progress and ETA, open the Dask dashboard while it runs, cancel, open the report.
import { useEffect, useState } from "preact/hooks";
import { api, errorMessage, unwrap, type Study } from "../api/client";
import { reported, useReportError } from "../errors";
import { fmtDuration } from "../format";
import { usePolling } from "../polling";
import {
  AXIS_LABEL, fieldErrors, INITIAL_FORM, NUMBER_AXES, PHYSICS, PRESETS, REQUIREMENT_LABEL, REQUIREMENTS, specText,
  studyForm, studySpec, type AxisForm, type NumberAxis, type RequirementKey, type StudyForm,
} from "../studyForm";

type Errors = Record<string, string>;

function FieldError({ path, errors }: { path: string; errors: Errors }) {
  return errors[path] ? <span class="field-error" role="alert" data-testid={`study-error-${path}`}>{errors[path]}</span> : null;
}

const value = (e: Event) => (e.target as HTMLInputElement).value;

function AxisInput({ axis, form, errors, set }: { axis: NumberAxis; form: AxisForm; errors: Errors; set: (a: AxisForm) => void }) {
  const path = `grid.${axis}`;
  const invalid = errors[path] ? "true" : undefined;
  return (
    <div class="study-axis">
      <span class="label">{AXIS_LABEL[axis]}</span>
      <select data-testid={`study-${axis}-mode`} value={form.mode} aria-label={`${AXIS_LABEL[axis]} as`}
        onChange={(e) => set({ ...form, mode: (e.target as HTMLSelectElement).value as AxisForm["mode"] })}>
        <option value="list">list</option><option value="range">start / stop / step</option>
      </select>
      {form.mode === "list" ? (
        <input data-testid={`study-${axis}`} size={16} value={form.list} placeholder="default" aria-invalid={invalid}
          title="numbers separated by commas; empty: the server's one default value" onInput={(e) => set({ ...form, list: value(e) })} />
      ) : (["start", "stop", "step"] as const).map((k) => (
        <input key={k} data-testid={`study-${axis}-${k}`} size={5} value={form[k]} placeholder={k} aria-invalid={invalid}
          aria-label={`${AXIS_LABEL[axis]} ${k}`} onInput={(e) => set({ ...form, [k]: value(e) })} />
      ))}
      <FieldError path={path} errors={errors} />
    </div>
  );
}

function Choices({ name, options, chosen, set }: { name: string; options: readonly string[]; chosen: string[]; set: (c: string[]) => void }) {
  return (
    <span class="study-choices">
      {options.map((o) => (
        <label key={o}><input type="checkbox" data-testid={`study-${name}-${o.replace(/ /g, "-")}`} checked={chosen.includes(o)}
          onChange={(e) => set((e.target as HTMLInputElement).checked ? [...chosen, o] : chosen.filter((c) => c !== o))} /> {o}</label>
      ))}
    </span>
  );
}

/** The requirements' defaults as the server's OpenAPI document states them (placeholders). */
function useRequirementDefaults(): Partial<Record<RequirementKey, string>> {
  const [defaults, setDefaults] = useState<Partial<Record<RequirementKey, string>>>({});
  useEffect(() => {
    fetch("/openapi.json").then((r) => r.json()).then((doc) => {
      const props = doc?.components?.schemas?.StudyRequirements?.properties ?? {};
      setDefaults(Object.fromEntries(REQUIREMENTS.filter((k) => props[k]?.default !== undefined).map((k) => [k, String(props[k].default)])));
    }).catch(() => undefined);
  }, []);
  return defaults;
}

function NewStudy({ submitted }: { submitted: () => void }) {
  const report = useReportError();
  const [form, setForm] = useState<StudyForm>(INITIAL_FORM);
  const [json, setJson] = useState<string | null>(null); // the JSON view's text when it is shown
  const [jsonNote, setJsonNote] = useState<string | null>(null);
  const [errors, setErrors] = useState<Errors>({});
  const [busy, setBusy] = useState(false);
  const defaults = useRequirementDefaults();
  const change = (part: Partial<StudyForm>) => setForm((f) => ({ ...f, ...part }));
  const editJson = (text: string) => {
    setJson(text);
    let doc: unknown;
    try {
      doc = JSON.parse(text);
    } catch (e) {
      setJsonNote(`not JSON (${(e as Error).message}); the form keeps its last valid spec`);
      return;
    }
    const parsed = studyForm(doc, form);
    if ("error" in parsed) setJsonNote(`${parsed.error}; the form keeps its last valid spec`);
    else {
      setJsonNote(null);
      setForm(parsed.form);
    }
  };
  const submit = async () => {
    if (busy) return;
    let body: unknown;
    if (json !== null) {
      if (jsonNote) { setErrors({ "": jsonNote }); return; }
      body = JSON.parse(json); // as typed: the server names what it cannot take
    } else {
      const spec = studySpec(form);
      if ("errors" in spec) { setErrors(spec.errors); return; }
      body = spec.body;
    }
    setBusy(true);
    try {
      // the body is what the form or the JSON view holds; the server validates it
      const answer = await api.POST("/api/studies", { body: body as never });
      if (answer.response.ok) {
        setErrors({});
        report(null);
        submitted();
      } else {
        setErrors(answer.response.status === 422 ? fieldErrors(answer.error) : { "": errorMessage(answer.response.status, answer.error) });
        report(errorMessage(answer.response.status, answer.error));
      }
    } finally {
      setBusy(false);
    }
  };
  const num = (key: "name" | "seed" | "frames_per_cell" | "chunk_frames", label: string, size: number, placeholder = "default") => (
    <label>{label} <input data-testid={`study-${key}`} size={size} value={form[key]} placeholder={placeholder}
      aria-invalid={errors[key] ? "true" : undefined} onInput={(e) => change({ [key]: value(e) })} />
      <FieldError path={key} errors={errors} /></label>
  );
  return (
    <details data-testid="new-study">
      <summary>new study</summary>
      <div class="study-bar">
        <button data-testid="study-view" onClick={() => {
          if (json === null) { setJson(specText(form)); setJsonNote(null); } else if (!jsonNote) setJson(null);
        }} title="the same spec as JSON, for power users">{json === null ? "JSON" : "form"}</button>
        <button data-testid="study-submit" onClick={submit} disabled={busy}>submit study</button>
      </div>
      <FieldError path="" errors={errors} />
      {json !== null ? (
        <div>
          <textarea data-testid="study-spec" rows={14} cols={70} value={json} onInput={(e) => editJson((e.target as HTMLTextAreaElement).value)} />
          {jsonNote && <span class="field-error" data-testid="study-json-note">{jsonNote}</span>}
          {Object.entries(errors).filter(([p]) => p).map(([p, m]) => <span key={p} class="field-error" data-testid={`study-error-${p}`}>{p}: {m}</span>)}
        </div>
      ) : (
        <div class="study-form">
          <fieldset><legend>study</legend>
            {num("name", "name", 14, "")}{num("frames_per_cell", "frames per cell", 5)}{num("seed", "seed", 4)}{num("chunk_frames", "frames per task", 4)}
          </fieldset>
          <fieldset><legend>grid (every combination is a cell)</legend>
            {NUMBER_AXES.map((a) => <AxisInput key={a} axis={a} form={form.axes[a]} errors={errors} set={(ax) => change({ axes: { ...form.axes, [a]: ax } })} />)}
            <div class="study-axis"><span class="label">physics</span>
              <Choices name="physics" options={PHYSICS} chosen={form.physics} set={(physics) => change({ physics })} />
              <FieldError path="grid.physics" errors={errors} /></div>
            <div class="study-axis"><span class="label">preset</span>
              <Choices name="preset" options={PRESETS} chosen={form.preset} set={(preset) => change({ preset })} />
              <FieldError path="grid.preset" errors={errors} /></div>
            <div class="study-axis"><span class="label">catalogs</span>
              <input data-testid="study-catalog" size={20} value={form.catalog} placeholder="paper-target" onInput={(e) => change({ catalog: value(e) })} />
              <FieldError path="grid.catalog" errors={errors} /></div>
          </fieldset>
          <fieldset class="study-req"><legend>requirements (empty: the campaign's)</legend>
            {REQUIREMENTS.map((k) => (
              <label key={k}>{REQUIREMENT_LABEL[k]} <input data-testid={`study-req-${k}`} size={5} value={form.requirements[k]}
                placeholder={defaults[k] ?? "default"} aria-invalid={errors[`requirements.${k}`] ? "true" : undefined}
                onInput={(e) => change({ requirements: { ...form.requirements, [k]: value(e) } })} />
                <FieldError path={`requirements.${k}`} errors={errors} /></label>
            ))}
          </fieldset>
        </div>
      )}
    </details>
  );
}

/** What a study's status cell says: a running study with no frame yet is starting its workers. */
function statusText(s: Study): string {
  if (s.status === "running" && s.frames_done === 0) return "running: starting workers";
  return s.error ? `${s.status}: ${s.error}` : s.status;
}

export function Studies() {
  const report = useReportError();
  const studies = usePolling(() => unwrap(api.GET("/api/studies")), 1000);
  const list = studies.data ?? [];
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
                <td data-testid={`study-status-${s.id}`}>{statusText(s)}</td>
                <td><progress max={s.frames_planned} value={s.frames_done} /> {s.frames_done} / {s.frames_planned} ({s.cells} cells)</td>
                <td>{s.status === "running" ? fmtDuration(s.eta_s) : "-"}</td>
                <td class="small">{s.cluster ?? "-"}{s.dashboard_url && (
                  <> <a data-testid={`study-dask-${s.id}`} href={s.dashboard_url} target="_blank" rel="noopener">Dask dashboard</a></>
                )}</td>
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
      <NewStudy submitted={studies.refresh} />
    </section>
  );
}
