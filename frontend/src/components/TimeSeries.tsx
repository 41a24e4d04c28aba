// Rolling plots of the six pose components (uPlot), with the lab's reference (dashed)
// when the source knows it.
import { useEffect, useRef } from "preact/hooks";
import uPlot from "uplot";
import "uplot/dist/uPlot.min.css";
import type { Pose } from "../api/client";

const REDRAW_MS = 250;

type Key = "x_mm" | "y_mm" | "z_mm" | "pitch_deg" | "yaw_deg" | "roll_deg";

function Chart({ history, keys, unit }: { history: Pose[]; keys: Key[]; unit: string }) {
  const el = useRef<HTMLDivElement>(null);
  const plot = useRef<uPlot | null>(null);
  const drawnAt = useRef(0);
  useEffect(() => {
    if (!el.current) return;
    const colors = ["#1f77b4", "#d62728", "#2ca02c"];
    plot.current = new uPlot(
      {
        width: 460, height: 170,
        scales: { x: { time: false } },
        axes: [{ label: "frame time (s)" }, { label: unit }],
        series: [
          {},
          ...keys.map((k, i) => ({ label: k, stroke: colors[i], width: 1.5 })),
          ...keys.map((k, i) => ({ label: `reference ${k}`, stroke: colors[i], width: 1, dash: [4, 4] })),
        ],
      },
      [[], ...keys.map(() => []), ...keys.map(() => [])],
      el.current,
    );
    return () => plot.current?.destroy();
  }, []);
  useEffect(() => {
    // Redrawn at most 4 times a second: plenty for a rolling 30 s plot, and the page
    // keeps its time for the images at 30 Hz.
    const now = performance.now();
    if (now - drawnAt.current < REDRAW_MS) return;
    drawnAt.current = now;
    const ok = history.filter((p) => p.ok);
    plot.current?.setData([
      ok.map((p) => p.frame_time_s),
      ...keys.map((k) => ok.map((p) => p[k] ?? null)),
      ...keys.map((k) => ok.map((p) => p.truth?.[k] ?? null)),
    ] as uPlot.AlignedData);
  }, [history]);
  return <div ref={el} />;
}

export function TimeSeries({ history }: { history: Pose[] }) {
  return (
    <section class="card">
      <h2>Pose over time</h2>
      <Chart history={history} keys={["x_mm", "y_mm"]} unit="mm" />
      <Chart history={history} keys={["z_mm"]} unit="mm" />
      <Chart history={history} keys={["pitch_deg", "yaw_deg", "roll_deg"]} unit="deg" />
    </section>
  );
}
