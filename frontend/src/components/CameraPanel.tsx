// Camera settings: read, change (token), show what the camera actually applied. Polled
// every 2 s, so that a campaign's per-set-point settings and their restore show; while a
// campaign runs no field can be changed (the server says why: `locked`), and while a
// recording records the modulation frequency cannot (`frequency_held`).
import { useState } from "preact/hooks";
import { api, unwrap, type Schemas } from "../api/client";
import { reported, useReportError } from "../errors";
import { usePolling } from "../polling";

type Settings = Schemas["CameraSettingsPublic"];
type Update = Schemas["CameraSettingsUpdate"];
type NumberKey = Exclude<keyof Update, "auto_exposure">;

export function CameraPanel() {
  const report = useReportError();
  const settings = usePolling(() => unwrap(api.GET("/api/camera/settings")), 2000);
  const [edit, setEdit] = useState<Partial<Record<keyof Update, string>>>({});
  const s = settings.data;
  if (!s) return null;
  const apply = async () => {
    const body: Update = {};
    for (const [k, v] of Object.entries(edit) as [keyof Update, string][]) {
      if (v === "") continue;
      if (k === "auto_exposure") body.auto_exposure = v === "true";
      else body[k as NumberKey] = Number(v);
    }
    const applied = await reported(report, () => unwrap(api.PUT("/api/camera/settings", { body })));
    if (applied) {
      settings.set(applied);
      setEdit({});
    }
  };
  const locked = s.locked ?? null;
  const held = (key: NumberKey) => locked ?? (key === "modulation_frequency_mhz" ? s.frequency_held ?? null : null);
  const field = (key: NumberKey, label: string, unit: string) => (
    <tr>
      <th>{label}</th><td>{String(s[key])} {unit}</td>
      <td><input size={7} aria-label={`${label} (${unit})`} data-testid={`cam-${key}`} value={edit[key] ?? ""}
        disabled={held(key) !== null} title={held(key) ?? undefined}
        onInput={(e) => setEdit({ ...edit, [key]: (e.target as HTMLInputElement).value })} /></td>
    </tr>
  );
  return (
    <section class="card">
      <h2>Camera</h2>
      {locked && <p class="small warn" data-testid="cam-locked">{locked}</p>}
      {!locked && s.frequency_held && (
        <p class="small warn" data-testid="cam-frequency-held">modulation held: {s.frequency_held}</p>
      )}
      <table class="small">
        <tbody>
          {field("frame_rate_hz", "frame rate", "Hz")}
          {field("integration_time_us", "integration time", "us")}
          {field("modulation_frequency_mhz", "modulation", "MHz")}
          <tr><th>auto exposure</th><td>{String(s.auto_exposure)}</td>
            <td><select data-testid="cam-auto_exposure" value={edit.auto_exposure ?? ""} disabled={locked !== null}
              onChange={(e) => setEdit({ ...edit, auto_exposure: (e.target as HTMLSelectElement).value })}>
              <option value="">-</option><option value="true">on</option><option value="false">off</option>
            </select></td></tr>
          <tr><th>unambiguous range</th><td colSpan={2}>{(s.unambiguous_range_mm / 1000).toFixed(2)} m</td></tr>
        </tbody>
      </table>
      <button data-testid="cam-apply" onClick={apply} disabled={locked !== null}>apply</button>
    </section>
  );
}
