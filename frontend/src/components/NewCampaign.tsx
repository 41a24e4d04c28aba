// Create a campaign from a generator: the server expands it into set-points and answers
// with the list and an estimated duration (a draft), which is shown before it is started.
import { useEffect, useRef, useState } from "preact/hooks";
import { api, unwrap, type Campaign } from "../api/client";
import {
  calibrationPreset, cameraText, campaignRequest, INITIAL_FORM, KIND_LABEL, KINDS, METADATA_FIELDS, params, profileText,
  takesFrames, withKind, type CampaignForm, type Kind, type Shape,
} from "../campaignForm";
import { reported, useReportError } from "../errors";

export function NewCampaign({ calibrationRequest = 0 }: { calibrationRequest?: number }) {
  const report = useReportError();
  const [form, setForm] = useState<CampaignForm>(INITIAL_FORM);
  const change = (part: Partial<CampaignForm>) => setForm((f) => ({ ...f, ...part }));
  const { name, kind, shape, fields: p, frames, recordRaw, integrationTimes, modulations, metadata } = form;
  const [draft, setDraft] = useState<Campaign | null>(null);
  const [formError, setFormError] = useState<string | null>(null);
  const ref = useRef<HTMLElement>(null);
  useEffect(() => {
    if (calibrationRequest === 0) return;
    setForm(calibrationPreset);
    ref.current?.scrollIntoView({ behavior: "smooth" });
  }, [calibrationRequest]);
  const [busy, setBusy] = useState(false);
  const create = async () => {
    const request = campaignRequest(form);
    setFormError("error" in request ? request.error : null);
    if ("error" in request || busy) return;
    setBusy(true);
    try {
      const created = await reported(report, () => unwrap(api.POST("/api/campaigns", { body: request.body })));
      if (created) setDraft(created);
    } finally {
      setBusy(false);
    }
  };
  const dynamic = (draft?.setpoints ?? []).some((sp) => sp.profile);
  const withCamera = (draft?.setpoints ?? []).some((sp) => sp.camera);
  return (
    <section class="card" ref={ref} data-testid="new-campaign">
      <h2>New campaign</h2>
      <div class="form">
        <label>name <input data-testid="new-name" value={name} onInput={(e) => change({ name: (e.target as HTMLInputElement).value })} /></label>
        <label>generator <select data-testid="new-kind" value={kind} onChange={(e) => setForm(withKind(form, (e.target as HTMLSelectElement).value as Kind))}>
          {KINDS.map((k) => <option key={k} value={k}>{KIND_LABEL[k] ?? k}</option>)}
        </select></label>
        {kind === "profile" && (
          <label>profile <select data-testid="new-profile-kind" value={shape} onChange={(e) => change({ shape: (e.target as HTMLSelectElement).value as Shape })}>
            <option value="sine">sine</option><option value="ramp">ramp</option>
          </select></label>
        )}
        {params(kind, shape).map(({ key, label, fallback, choices, optional }) => choices ? (
          <label key={key}>{label} <select data-testid={`new-${key}`} value={p[key] || fallback}
            onChange={(e) => change({ fields: { ...p, [key]: (e.target as HTMLSelectElement).value } })}>
            {choices.map((c) => <option key={c} value={c}>{c}</option>)}
          </select></label>
        ) : (
          <label key={key}>{label} <input data-testid={`new-${key}`} size={14} value={p[key] ?? ""}
            placeholder={fallback} title={optional ? `empty: not sent (${fallback})` : `empty: ${fallback}`}
            onInput={(e) => change({ fields: { ...p, [key]: (e.target as HTMLInputElement).value } })} /></label>
        ))}
        {!takesFrames(kind) ? (
          <span class="small" data-testid="new-frames-na" title="every frame of the rests and the profile is kept">frames per set-point: does not apply</span>
        ) : (
          <label>frames per set-point <input data-testid="new-frames" size={5} value={frames} onInput={(e) => change({ frames: (e.target as HTMLInputElement).value })} /></label>
        )}
        <label title="every set-point is measured at each integration time (auto exposure off); empty: the camera as it is">
          integration times us (list) <input data-testid="new-integration" size={14} value={integrationTimes} placeholder="camera's own"
            onInput={(e) => change({ integrationTimes: (e.target as HTMLInputElement).value })} /></label>
        <label title="every set-point at each modulation frequency the camera supports; empty: the camera's own">
          modulation MHz (list) <input data-testid="new-modulation" size={8} value={modulations} placeholder="camera's own"
            onInput={(e) => change({ modulations: (e.target as HTMLInputElement).value })} /></label>
        <label title="every measured frame pair in a recording (HDF5, also downloadable as MCAP for Foxglove / Rerun)">
          <input type="checkbox" data-testid="new-record-raw" checked={recordRaw}
            onChange={(e) => change({ recordRaw: (e.target as HTMLInputElement).checked })} /> keep raw frames</label>
      </div>
      <div class="form" data-testid="new-metadata">
        {METADATA_FIELDS.map(({ key, label, title }) => (
          <label key={key} title={title}>{label} <input data-testid={`new-${key}`} size={key === "notes" ? 30 : 14} value={metadata[key]}
            placeholder={key.startsWith("camera_") ? "from the device" : ""}
            onInput={(e) => change({ metadata: { ...metadata, [key]: (e.target as HTMLInputElement).value } })} /></label>
        ))}
        <button data-testid="new-create" onClick={create} disabled={busy}>create draft</button>
      </div>
      {formError && <p class="field-error" role="alert" data-testid="new-error">{formError}</p>}
      {draft && (
        <div data-testid="draft">
          <p class="small">Draft {draft.id} "{draft.name}": {draft.n_setpoints} set-points, estimated
            {" "}{Math.round(draft.estimated_duration_s)} s. Start it in the campaign list.</p>
          <table class="small">
            <thead><tr><th>#</th><th>yaw deg</th><th>pitch deg</th><th>roll deg</th><th>rail mm</th>{withCamera && <th>camera</th>}{dynamic && <th>profile</th>}</tr></thead>
            <tbody>
              {(draft.setpoints ?? []).slice(0, 30).map((sp) => (
                <tr key={sp.index}><td>{sp.index}</td><td>{sp.yaw_deg ?? "-"}</td><td>{sp.pitch_deg ?? "-"}</td><td>{sp.roll_deg ?? "-"}</td><td>{sp.rail_mm ?? "-"}</td>
                  {withCamera && <td data-testid={`draft-camera-${sp.index}`}>{cameraText(sp.camera)}</td>}
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
