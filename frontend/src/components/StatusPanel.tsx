// Device status (state, delivered frame rate, last error) and the pipeline's per-stage
// timings of the latest frame.
import { useEffect, useState } from "preact/hooks";
import { api, type Pose } from "../api/client";
import type { components } from "../api/schema";

type Devices = components["schemas"]["DevicesPublic"];

export function StatusPanel({ pose, onError }: { pose: Pose | null; onError: (m: string | null) => void }) {
  const [dev, setDev] = useState<Devices | null>(null);
  useEffect(() => {
    const poll = () => api<Devices>("GET", "/api/devices").then(setDev).catch((e) => onError(e.message));
    poll();
    const t = window.setInterval(poll, 1000);
    return () => window.clearInterval(t);
  }, []);
  const timings = Object.entries(pose?.timings_ms ?? {});
  return (
    <section class="card">
      <h2>Devices and timings</h2>
      {dev && (
        <table class="small" data-testid="devices">
          <tbody>
            <tr><th>camera</th><td data-testid="camera-state">{dev.camera.state}</td>
              <td data-testid="camera-rate">{dev.camera.frame_rate_hz.toFixed(1)} frames/s</td>
              <td>{dev.camera.driver}, catalog {dev.camera.catalog}</td></tr>
            <tr><th>motion</th><td data-testid="motion-state">{dev.motion.state}</td><td>{dev.motion.driver}</td><td /></tr>
            {[dev.camera, dev.motion].filter((d) => d.last_error).map((d) => (
              <tr key={d.driver}><td colSpan={4} class="error">{d.driver}: {d.last_error}</td></tr>
            ))}
          </tbody>
        </table>
      )}
      {timings.length > 0 && (
        <table class="small" data-testid="timings">
          <tbody>
            {timings.map(([stage, ms]) => (
              <tr key={stage}><th>{stage}</th><td>{ms.toFixed(2)} ms</td></tr>
            ))}
          </tbody>
        </table>
      )}
    </section>
  );
}
