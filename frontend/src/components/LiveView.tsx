// Gray and distance images side by side, colour-mapped here from the raw uint16 frames at
// the camera's own resolution (the frames' aspect ratio) and gray full scale;
// overlays drawn here and toggled without a server round-trip: the active pixel set,
// candidate blobs, matched reflectors with catalog ids (an orange ring and "saturated"
// where the server says a reflector's pixels reach full scale, with a warning under the
// images), and rejected blobs with the gate that refused them. Each drawn frame is
// acknowledged (flow control, see live.ts).
import { useEffect, useLayoutEffect, useRef, useState } from "preact/hooks";
import type { Pose } from "../api/client";
import type { Shown } from "../live";
import { activePixels, distancePixels, grayPixels, grayTop, turboCss } from "../colormap";
import type { RawFrame } from "../rawframe";
import { reflectorLabel, saturationWarning } from "../saturation";
import { wrapNotice } from "../wrap";

// Overlay canvas pixels per image pixel: about 640 canvas pixels across whatever the
// camera's width (2 for the TOFcam-660's 320, 1 for an Azure Kinect's 640), so that marks
// and labels drawn in canvas pixels keep their size on the page.
const OVERLAY_WIDTH = 640;
const MATCHED_COLOUR = "#3ddc6a";
const SATURATED_COLOUR = "#ff8c1a";

type Layers = { active: boolean; candidates: boolean; matched: boolean; rejected: boolean };
const LAYER_LABELS: Record<keyof Layers, string> = {
  active: "active pixels (gray ≥ I_t)",
  candidates: "candidate blobs",
  matched: "matched reflectors (catalog id)",
  rejected: "rejected blobs (reason)",
};

declare global {
  interface Window { __tofposeFramesDrawn?: number } // read by bench/live.py
}

function useImage(draw: (f: RawFrame, img: ImageData) => void, raw: RawFrame | undefined) {
  const ref = useRef<HTMLCanvasElement>(null);
  useEffect(() => {
    const c = ref.current;
    if (!c || !raw) return;
    if (c.width !== raw.width || c.height !== raw.height) {
      c.width = raw.width;
      c.height = raw.height;
    }
    const ctx = c.getContext("2d")!;
    const img = ctx.createImageData(raw.width, raw.height);
    draw(raw, img);
    ctx.putImageData(img, 0, 0);
  }, [raw]);
  return ref;
}

function Overlay({ shown, layers }: { shown: Shown | null; layers: Layers }) {
  const ref = useRef<HTMLCanvasElement>(null);
  const mask = useRef<HTMLCanvasElement | null>(null);
  // drawn in the same commit as the text beside it (the saturation warning): a deferred
  // effect left a moment where the warning counted the new frame's saturated reflectors
  // and the overlay still labelled the last frame's
  useLayoutEffect(() => {
    const c = ref.current;
    if (!c || !shown) return;
    const { raw, pose } = shown;
    const W = raw.width * raw.step;
    const H = raw.height * raw.step;
    const SCALE = Math.max(1, Math.round(OVERLAY_WIDTH / W));
    if (c.width !== W * SCALE || c.height !== H * SCALE) {
      c.width = W * SCALE;
      c.height = H * SCALE;
    }
    const ctx = c.getContext("2d")!;
    ctx.clearRect(0, 0, c.width, c.height);
    const labels: string[] = []; // the reflector labels drawn, in the DOM as data-labels
    c.dataset.labels = "";
    if (!pose) return;
    const px = (u: number) => (u + 0.5) * SCALE;
    if (layers.active && pose.active_threshold_counts != null) {
      mask.current ??= document.createElement("canvas");
      const m = mask.current;
      m.width = raw.width;
      m.height = raw.height;
      const mctx = m.getContext("2d")!;
      const img = mctx.createImageData(raw.width, raw.height);
      activePixels(raw, pose.active_threshold_counts, img);
      mctx.putImageData(img, 0, 0);
      ctx.imageSmoothingEnabled = false;
      ctx.drawImage(m, 0, 0, c.width, c.height);
    }
    ctx.lineWidth = 1.5;
    ctx.font = "13px sans-serif";
    if (layers.candidates) {
      ctx.strokeStyle = "#ffd400";
      const all = [...pose.matched.map((b) => [b.u_px, b.v_px]), ...pose.unmatched.map((b) => [b.u_px, b.v_px])];
      for (const [u, v] of all) ctx.strokeRect(px(u) - 9, px(v) - 9, 18, 18);
    }
    if (layers.matched) {
      for (const m of pose.matched) {
        const r = Math.max(Math.sqrt(m.area_px / Math.PI), 1) * SCALE + 3;
        ctx.strokeStyle = m.saturated ? SATURATED_COLOUR : MATCHED_COLOUR;
        ctx.fillStyle = m.saturated ? SATURATED_COLOUR : "#ffffff";
        ctx.lineWidth = m.saturated ? 3 : 1.5;
        ctx.beginPath();
        ctx.arc(px(m.u_px), px(m.v_px), r, 0, 2 * Math.PI);
        ctx.moveTo(px(m.u_px) - 4, px(m.v_px));
        ctx.lineTo(px(m.u_px) + 4, px(m.v_px));
        ctx.moveTo(px(m.u_px), px(m.v_px) - 4);
        ctx.lineTo(px(m.u_px), px(m.v_px) + 4);
        ctx.stroke();
        const label = reflectorLabel(m);
        ctx.fillText(label, px(m.u_px) + r + 2, px(m.v_px) - r);
        labels.push(label);
      }
      ctx.lineWidth = 1.5;
      c.dataset.labels = labels.join("|");
    }
    if (layers.rejected) {
      ctx.strokeStyle = "#ff4dd2";
      ctx.fillStyle = "#ff9de8";
      for (const b of pose.rejected ?? []) {
        const r = Math.max(b.diameter_px / 2, 2) * SCALE + 2;
        ctx.beginPath();
        ctx.moveTo(px(b.u_px) - r, px(b.v_px) - r);
        ctx.lineTo(px(b.u_px) + r, px(b.v_px) + r);
        ctx.moveTo(px(b.u_px) + r, px(b.v_px) - r);
        ctx.lineTo(px(b.u_px) - r, px(b.v_px) + r);
        ctx.stroke();
        ctx.fillText(b.reason, px(b.u_px) + r + 2, px(b.v_px) + 4);
      }
    }
  }, [shown, layers]);
  return <canvas ref={ref} class="overlay" data-testid="overlay" />;
}

function ColourBar({ range }: { range: [number, number] | null }) {
  if (!range) return null;
  const stops = Array.from({ length: 11 }, (_, i) => turboCss(i / 10)).join(", ");
  return (
    <div class="colourbar" data-testid="colourbar">
      <span>{(range[0] / 1000).toFixed(2)} m</span>
      <div class="bar" style={{ background: `linear-gradient(to right, ${stops})` }} />
      <span>{(range[1] / 1000).toFixed(2)} m</span>
    </div>
  );
}

export function LiveView({ shown, onDrawn }: { shown: Shown | null; onDrawn: (frameIndex: number) => void }) {
  const [layers, setLayers] = useState<Layers>({ active: false, candidates: true, matched: true, rejected: true });
  const [range, setRange] = useState<[number, number] | null>(null);
  const raw = shown?.raw;
  const warning = saturationWarning(shown?.pose);
  const wrapped = wrapNotice(shown?.pose);
  const grayRef = useImage(grayPixels, raw);
  const distRef = useImage((f, img) => setRange(distancePixels(f, img)), raw);
  // the camera's own shape (640 x 576 for an Azure Kinect), not the TOFcam-660's 4:3
  const aspect = raw ? { aspectRatio: `${raw.width * raw.step} / ${raw.height * raw.step}` } : undefined;
  useEffect(() => {
    if (!raw) return;
    window.__tofposeFramesDrawn = (window.__tofposeFramesDrawn ?? 0) + 1;
    onDrawn(raw.frameIndex);
  }, [raw]);
  return (
    <section class="card">
      <h2>Live images {raw && <span class="small" data-testid="frame-index">frame {raw.frameIndex}</span>}</h2>
      <div class="toggles">
        {(Object.keys(LAYER_LABELS) as (keyof Layers)[]).map((k) => (
          <label key={k}>
            <input type="checkbox" checked={layers[k]} data-testid={`toggle-${k}`}
              onChange={() => setLayers({ ...layers, [k]: !layers[k] })} /> {LAYER_LABELS[k]}
          </label>
        ))}
      </div>
      {warning && <p class="warn" role="status" data-testid="saturation-warning">{warning}</p>}
      {wrapped && <p class="small" role="status" data-testid="wrap-notice">{wrapped}</p>}
      <div class="images">
        {(["gray", "distance"] as const).map((k) => (
          <figure key={k}>
            <div class="frame" style={aspect} data-testid={`frame-${k}`}>
              <canvas ref={k === "gray" ? grayRef : distRef} class="image" aria-label={`${k} image`} data-testid={`image-${k}`} />
              {!raw && <div class="placeholder">waiting for images</div>}
              <Overlay shown={shown} layers={layers} />
            </div>
            <figcaption>
              {k === "gray" ? <span data-testid="gray-scale">gray (counts 0–{raw ? grayTop(raw) : "?"}, gamma 0.5)</span> : <>distance (turbo, 2nd–98th percentile; black = invalid) <ColourBar range={range} /></>}
            </figcaption>
          </figure>
        ))}
      </div>
    </section>
  );
}
