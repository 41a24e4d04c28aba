// The latency and dropped-frame readout's numbers, from each /ws/live pose message: the
// server measures and summarises them (docs/server.md, "Latency and dropped frames");
// the page only picks them out and formats them.
import type { Schemas } from "./api/client";

type Summary = Schemas["LatencySummaryPublic"];
type Dropped = Schemas["DroppedFramesPublic"];

/** What a pose message's `latency` holds (backend FrameLatencyPublic). */
export type FrameLatency = {
  capture_to_pose: Summary;
  capture_to_sent: Summary;
  dropped_total: Dropped;
  window_s: number;
};

/** The readout's state: the server's window statistics and this client's own drops. */
export type LiveLatency = {
  stats: FrameLatency;
  /** frames this client's mailbox dropped since it connected */
  droppedThisClient: number;
  /** capture -> this message handed to our socket, for the newest frame */
  captureToSentMs: number | null;
};

/** The readout's state from a pose message, or null when it carries no statistics. */
export function latencyOf(message: { dropped?: number; latency?: FrameLatency | null; capture_to_sent_ms?: number | null }): LiveLatency | null {
  if (!message.latency) return null;
  return {
    stats: message.latency,
    droppedThisClient: message.dropped ?? 0,
    captureToSentMs: message.capture_to_sent_ms ?? null,
  };
}

const ms = (v: number | null | undefined) => (v === null || v === undefined ? "–" : `${Math.round(v)} ms`);

/** "latency 12 ms median / 18 ms p95": capture -> WebSocket sent over the window. */
export function latencyLine(l: LiveLatency): string {
  const s = l.stats.capture_to_sent;
  return `latency ${ms(s.median_ms)} median / ${ms(s.p95_ms)} p95`;
}

/** "dropped: camera 0, pipeline 3, this client 0" (camera "n/a": it has no counter). */
export function droppedLine(l: LiveLatency): string {
  const d = l.stats.dropped_total;
  const camera = d.camera === null || d.camera === undefined ? "n/a" : String(d.camera);
  return `dropped: camera ${camera}, pipeline ${d.pipeline}, this client ${l.droppedThisClient}`;
}

/** The readout's tooltip: what the numbers are and the pose-ready latency. */
export function latencyTitle(l: LiveLatency): string {
  const p = l.stats.capture_to_pose;
  return `capture → WebSocket sent over the last ${l.stats.window_s} s (${l.stats.capture_to_sent.n} messages); ` +
    `capture → pose ready ${ms(p.median_ms)} median / ${ms(p.p95_ms)} p95; ` +
    `drops counted since the server started (this client: since it connected)`;
}
