// One store for everything that arrives on /ws/live: reconnects by itself, marks the
// data stale when no frame has come for a while, and hands raw frames to the page at most
// once per animation frame (the newest wins; the server waits for our acknowledgement
// before it sends more than RAW_CREDIT, so nothing queues). The API key the page keeps
// (sessionStorage, api/client.ts) goes in the handshake as the subprotocol
// "tofpose.bearer.<key>", never in the URL (docs/server.md, Security).
import { token, type Pose } from "./api/client";
import { latencyOf, type LiveLatency } from "./latency";
import { sampleOf } from "./plotSeries";
import { SampleBuffer } from "./plotWindow";
import { parseRawFrame, type RawFrame } from "./rawframe";

export type Shown = { raw: RawFrame; pose: Pose | null };
export type LiveState = {
  connected: boolean;
  stale: boolean;
  pose: Pose | null;
  shown: Shown | null; // the newest raw frame and the pose of that same frame
  /** the plotted numbers of the last 10 minutes (mutable: its version counts the pushes) */
  samples: SampleBuffer;
  /** the server's latency statistics and this client's drops, from the newest pose message */
  latency?: LiveLatency | null;
};

const STALE_AFTER_MS = 2000;
const RAW_CREDIT = 2;
const BEARER = "tofpose.bearer";

/** The subprotocols that carry the key: the server accepts "tofpose.bearer" (a browser
 * fails a handshake whose chosen subprotocol it did not offer) and reads the key from
 * the other; none without a key (reads are open on loopback). */
export function liveProtocols(key: string | null): string[] {
  return key ? [BEARER, `${BEARER}.${key}`] : [];
}

export type LiveHandle = { close: () => void; ack: (frameIndex: number) => void };

export function connectLive(onChange: (s: LiveState) => void): LiveHandle {
  const state: LiveState = { connected: false, stale: true, pose: null, shown: null, samples: new SampleBuffer() };
  const recent = new Map<number, Pose>(); // pose by frame index, to pair with raw frames
  let ws: WebSocket | null = null;
  let lastFrame = 0;
  let closed = false;
  let retry: number | undefined;
  let scheduled = false;
  let pendingRaw: RawFrame | null = null;

  // One render per animation frame however many messages arrived since the last one.
  const emit = () => {
    if (scheduled) return;
    scheduled = true;
    requestAnimationFrame(() => {
      scheduled = false;
      if (pendingRaw) {
        state.shown = { raw: pendingRaw, pose: recent.get(pendingRaw.frameIndex) ?? null };
        pendingRaw = null;
      }
      onChange({ ...state });
    });
  };

  const open = () => {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${proto}://${location.host}/ws/live`, liveProtocols(token()));
    ws.binaryType = "arraybuffer";
    ws.onopen = () => {
      state.connected = true;
      ws?.send(JSON.stringify({ raw: true, raw_credit: RAW_CREDIT, image_every: 1, image_step: 1 }));
      emit();
    };
    ws.onmessage = (ev) => {
      if (ev.data instanceof ArrayBuffer) {
        const raw = parseRawFrame(ev.data);
        if (pendingRaw) ack(pendingRaw.frameIndex); // superseded before it was drawn
        pendingRaw = raw;
        emit();
        return;
      }
      const m = JSON.parse(ev.data);
      if (m.type === "pose") {
        const p = m.data as Pose;
        state.pose = p;
        state.latency = latencyOf(m);
        recent.set(p.frame_index, p);
        if (recent.size > 60) recent.delete(recent.keys().next().value!);
        state.samples.push(sampleOf(p));
        lastFrame = Date.now();
        state.stale = false;
        emit();
      }
    };
    ws.onclose = () => {
      state.connected = false;
      emit();
      if (!closed) retry = window.setTimeout(open, 1000);
    };
  };
  const ack = (frameIndex: number) => {
    if (ws?.readyState === WebSocket.OPEN) ws.send(JSON.stringify({ ack: frameIndex }));
  };
  open();
  const timer = window.setInterval(() => {
    const stale = Date.now() - lastFrame > STALE_AFTER_MS;
    if (stale !== state.stale) {
      state.stale = stale;
      emit();
    }
  }, 500);
  return {
    ack,
    close: () => {
      closed = true;
      window.clearInterval(timer);
      window.clearTimeout(retry);
      ws?.close();
    },
  };
}
