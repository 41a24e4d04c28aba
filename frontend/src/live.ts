// One store for everything that arrives on /ws/live: reconnects by itself, and marks
// the data stale when no frame has come for a while.
import type { Pose } from "./api/client";

export type Images = { gray?: string; distance?: string; frameIndex?: number };
export type LiveState = {
  connected: boolean;
  stale: boolean;
  pose: Pose | null;
  images: Images;
  history: Pose[];
};

const STALE_AFTER_MS = 2000;
const HISTORY = 300;

export function connectLive(onChange: (s: LiveState) => void): () => void {
  const state: LiveState = { connected: false, stale: true, pose: null, images: {}, history: [] };
  let ws: WebSocket | null = null;
  let lastFrame = 0;
  let closed = false;
  let retry: number | undefined;
  const emit = () => onChange({ ...state, images: { ...state.images } });

  const open = () => {
    const proto = location.protocol === "https:" ? "wss" : "ws";
    ws = new WebSocket(`${proto}://${location.host}/ws/live`);
    ws.onopen = () => {
      state.connected = true;
      ws?.send(JSON.stringify({ images: ["gray", "distance"], image_every: 1, image_step: 1 }));
      emit();
    };
    ws.onmessage = (ev) => {
      const m = JSON.parse(ev.data);
      if (m.type === "pose") {
        state.pose = m.data as Pose;
        state.history = [...state.history.slice(-(HISTORY - 1)), m.data];
        lastFrame = Date.now();
        state.stale = false;
        emit();
      } else if (m.type === "image") {
        state.images[m.kind as "gray" | "distance"] = `data:image/png;base64,${m.png_base64}`;
        state.images.frameIndex = m.frame_index;
        emit();
      }
    };
    ws.onclose = () => {
      state.connected = false;
      emit();
      if (!closed) retry = window.setTimeout(open, 1000);
    };
  };
  open();
  const timer = window.setInterval(() => {
    const stale = Date.now() - lastFrame > STALE_AFTER_MS;
    if (stale !== state.stale) {
      state.stale = stale;
      emit();
    }
  }, 500);
  return () => {
    closed = true;
    window.clearInterval(timer);
    window.clearTimeout(retry);
    ws?.close();
  };
}
