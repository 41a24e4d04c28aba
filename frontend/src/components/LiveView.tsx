// Gray and distance images side by side; overlays drawn here, toggled without a server
// round-trip: matched reflectors (circle, centroid, catalog id) and unmatched blobs.
import { useEffect, useRef, useState } from "preact/hooks";
import type { Pose } from "../api/client";
import type { Images } from "../live";

const W = 320;
const H = 240;
const SCALE = 2;

function Overlay({ pose, matched, unmatched }: { pose: Pose | null; matched: boolean; unmatched: boolean }) {
  const ref = useRef<HTMLCanvasElement>(null);
  useEffect(() => {
    const c = ref.current?.getContext("2d");
    if (!c) return;
    c.clearRect(0, 0, W * SCALE, H * SCALE);
    if (!pose) return;
    const px = (u: number) => (u + 0.5) * SCALE;
    c.lineWidth = 1.5;
    if (matched) {
      c.strokeStyle = "#3ddc6a";
      c.fillStyle = "#ffffff";
      c.font = "13px sans-serif";
      for (const m of pose.matched) {
        const r = Math.max(Math.sqrt(m.area_px / Math.PI), 1) * SCALE + 3;
        c.beginPath();
        c.arc(px(m.u_px), px(m.v_px), r, 0, 2 * Math.PI);
        c.stroke();
        c.beginPath();
        c.moveTo(px(m.u_px) - 4, px(m.v_px));
        c.lineTo(px(m.u_px) + 4, px(m.v_px));
        c.moveTo(px(m.u_px), px(m.v_px) - 4);
        c.lineTo(px(m.u_px), px(m.v_px) + 4);
        c.stroke();
        c.fillText(String(m.catalog_id), px(m.u_px) + r + 2, px(m.v_px) - r);
      }
    }
    if (unmatched) {
      c.strokeStyle = "#ff4d4d";
      for (const b of pose.unmatched) {
        c.beginPath();
        c.arc(px(b.u_px), px(b.v_px), 7, 0, 2 * Math.PI);
        c.stroke();
      }
    }
  }, [pose, matched, unmatched]);
  return <canvas ref={ref} class="overlay" width={W * SCALE} height={H * SCALE} data-testid="overlay" />;
}

export function LiveView({ images, pose }: { images: Images; pose: Pose | null }) {
  const [matched, setMatched] = useState(true);
  const [unmatched, setUnmatched] = useState(true);
  return (
    <section class="card">
      <h2>Live images</h2>
      <div class="toggles">
        <label><input type="checkbox" checked={matched} onChange={() => setMatched(!matched)} data-testid="toggle-matched" /> matched reflectors</label>
        <label><input type="checkbox" checked={unmatched} onChange={() => setUnmatched(!unmatched)} data-testid="toggle-unmatched" /> unmatched blobs</label>
      </div>
      <div class="images">
        {(["gray", "distance"] as const).map((k) => (
          <figure key={k}>
            <div class="frame">
              {images[k] ? <img src={images[k]} alt={`${k} image`} width={W * SCALE} height={H * SCALE} /> : <div class="placeholder">waiting for images</div>}
              <Overlay pose={pose} matched={matched} unmatched={unmatched} />
            </div>
            <figcaption>{k === "gray" ? "gray (gamma 0.5)" : "distance (turbo, near = blue, 2nd-98th percentile; black = invalid)"}</figcaption>
          </figure>
        ))}
      </div>
    </section>
  );
}
