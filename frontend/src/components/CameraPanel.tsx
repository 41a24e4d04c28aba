// Camera settings: read, change (token), show what the camera actually applied.
import { useState } from "preact/hooks";
import { api, unwrap, type Schemas } from "../api/client";
import { reported, useReportError } from "../errors";
import { usePolling } from "../polling";

type Settings = Schemas["CameraSettingsPublic"];
type Update = Schemas["CameraSettingsUpdate"];
type NumberKey = Exclude<keyof Update, "auto_exposure">;

export function CameraPanel() {
  const report = useReportError();
  const settings = usePolling(() => unwrap(api.GET("/api/camera/settings")), null);
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
  const field = (key: NumberKey, label: string, unit: string) => (
    <tr>
      <th>{label}</th><td>{String(s[key])} {unit}</td>
      <td><input size={7} aria-label={`${label} (${unit})`} data-testid={`cam-${key}`} value={edit[key] ?? ""}
        onInput={(e) => setEdit({ ...edit, [key]: (e.target as HTMLInputElement).value })} /></td>
    </tr>
  );
  return (
    <section class="card">
      <h2>Camera</h2>
      <table class="small">
        <tbody>
          {field("frame_rate_hz", "frame rate", "Hz")}
          {field("integration_time_us", "integration time", "us")}
          {field("modulation_frequency_mhz", "modulation", "MHz")}
          <tr><th>auto exposure</th><td>{String(s.auto_exposure)}</td>
            <td><select data-testid="cam-auto_exposure" value={edit.auto_exposure ?? ""}
              onChange={(e) => setEdit({ ...edit, auto_exposure: (e.target as HTMLSelectElement).value })}>
              <option value="">-</option><option value="true">on</option><option value="false">off</option>
            </select></td></tr>
          <tr><th>unambiguous range</th><td colSpan={2}>{(s.unambiguous_range_mm / 1000).toFixed(2)} m</td></tr>
        </tbody>
      </table>
      <button data-testid="cam-apply" onClick={apply}>apply</button>
    </section>
  );
}
