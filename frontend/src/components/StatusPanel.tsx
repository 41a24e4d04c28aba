// Device status (state, model, firmware, address and link, delivered frame rate, last error),
// whether the pipeline's compiled kernels are ready and which implementation gives the poses
// meanwhile, and its per-stage timings of the latest frame.
import { api, unwrap, type Pose, type Schemas } from "../api/client";
import { usePolling } from "../polling";

type Device = Schemas["DeviceStatePublic"];

// "ESPROS TOFcam-660 3.59 at 127.0.0.2 (link down)": what the driver says of its device.
function describe(d: Device): string {
  const parts = [d.model ?? d.driver];
  if (d.firmware) parts.push(d.firmware);
  if (d.address) parts.push(`at ${d.address}`);
  if (d.link === "down") parts.push("(link down)");
  return parts.join(" ");
}

// Which implementation of the pipeline gives the live poses: the reference one (NumPy/SciPy)
// while the compiled kernels compile on a first start, then the compiled one.
function implementation(p: Schemas["PipelineStatePublic"]): string {
  return p.implementation === null ? "no poses yet" : `${p.implementation} implementation`;
}

export function StatusPanel({ pose }: { pose: Pose | null }) {
  const dev = usePolling(() => unwrap(api.GET("/api/devices")), 1000).data;
  const timings = Object.entries(pose?.timings_ms ?? {});
  return (
    <section class="card">
      <h2>Devices and timings</h2>
      {dev && (
        <table class="small" data-testid="devices">
          <tbody>
            <tr><th>camera</th><td data-testid="camera-state">{dev.camera.state}</td>
              <td data-testid="camera-rate">{dev.camera.frame_rate_hz.toFixed(1)} frames/s</td>
              <td data-testid="camera-device">{describe(dev.camera)}, catalog {dev.camera.catalog}</td></tr>
            <tr><th>motion</th><td data-testid="motion-state">{dev.motion.state}</td><td />
              <td data-testid="motion-device">{describe(dev.motion)}</td></tr>
            <tr><th>pipeline</th><td data-testid="pipeline-state">{dev.pipeline.state}
                {dev.pipeline.state === "compiling" ? ` ${dev.pipeline.seconds.toFixed(0)} s` : ""}</td>
              <td data-testid="pipeline-implementation">{implementation(dev.pipeline)}</td>
              <td class="small" data-testid="pipeline-detail">{dev.pipeline.detail}</td></tr>
            {[dev.camera, dev.motion].filter((d) => d.last_error).map((d) => (
              <tr key={d.driver}><td colSpan={4} class="error">{d.driver}: {d.last_error}</td></tr>
            ))}
          </tbody>
        </table>
      )}
      {/* room for the longest list (acquisition's stages), so that a tracked frame's
          shorter one does not move everything below this panel up and down */}
      <div class="timings-box">
        {timings.length > 0 && (
          <table class="small" data-testid="timings">
            <tbody>
              {timings.map(([stage, ms]) => (
                <tr key={stage}><th>{stage}</th><td>{ms.toFixed(2)} ms</td></tr>
              ))}
            </tbody>
          </table>
        )}
      </div>
    </section>
  );
}
