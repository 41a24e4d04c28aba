// Camera settings: read, change (token), show what the camera actually applied.
import { useEffect, useState } from "preact/hooks";
import { api } from "../api/client";
import type { components } from "../api/schema";

type Settings = components["schemas"]["CameraSettingsPublic"];

export function CameraPanel({ onError }: { onError: (m: string | null) => void }) {
  const [s, setS] = useState<Settings | null>(null);
  const [edit, setEdit] = useState<Record<string, string>>({});
  useEffect(() => {
    api<Settings>("GET", "/api/camera/settings").then(setS).catch((e) => onError(e.message));
  }, []);
  if (!s) return null;
  const apply = async () => {
    const body: Record<string, number | boolean> = {};
    for (const [k, v] of Object.entries(edit)) if (v !== "") body[k] = k === "auto_exposure" ? v === "true" : Number(v);
    try {
      setS(await api<Settings>("PUT", "/api/camera/settings", body));
      setEdit({});
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    }
  };
  const field = (key: keyof Settings, label: string, unit: string) => (
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
