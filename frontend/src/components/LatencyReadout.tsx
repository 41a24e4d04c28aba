// A compact line near the pose: the latency a client of the live stream sees (capture ->
// WebSocket sent, median and 95th percentile over the server's window) and the frames
// dropped by the camera, the pipeline and this client.
import { droppedLine, latencyLine, latencyTitle, type LiveLatency } from "../latency";

export function LatencyReadout({ latency }: { latency: LiveLatency | null }) {
  if (!latency) return <p class="small latency" data-testid="latency">latency: waiting for frames</p>;
  return (
    <p class="small latency" data-testid="latency" title={latencyTitle(latency)}>
      <span data-testid="latency-ms">{latencyLine(latency)}</span> · <span data-testid="latency-dropped">{droppedLine(latency)}</span>
    </p>
  );
}
