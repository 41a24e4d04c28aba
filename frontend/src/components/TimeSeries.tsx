// Rolling plots of the six pose components and of the target's angular rate (uPlot),
// with the lab's reference (dashed) when the source knows it.
import { useEffect, useRef } from "preact/hooks";
import uPlot from "uplot";
import "uplot/dist/uPlot.min.css";
import type { Pose } from "../api/client";

const REDRAW_MS = 250;

type Key = "x_mm" | "y_mm" | "z_mm" | "pitch_deg" | "yaw_deg" | "roll_deg";

/** One plotted line: its label, its value in a frame, and the lab reference's, if any. */
interface Line {
  label: string;
  value: (p: Pose) => number | null | undefined;
  reference?: (p: Pose) => number | null | undefined;
}

const poseLine = (k: Key): Line => ({ label: k, value: (p) => p[k], reference: (p) => p.truth?.[k] });

const rateLine = (axis: number, name: string): Line => ({
  label: `rate ${name} (camera)`,
  value: (p) => p.angular_rate_deg_s?.[axis],
});

function Chart({ history, lines, unit, shown, testid }: {
  history: Pose[]; lines: Line[]; unit: string; shown: (p: Pose) => boolean; testid?: string;
}) {
  const el = useRef<HTMLDivElement>(null);
  const plot = useRef<uPlot | null>(null);
  const drawnAt = useRef(0);
  const withRef = lines.filter((l) => l.reference);
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
          ...lines.map((l, i) => ({ label: l.label, stroke: colors[i], width: 1.5 })),
          ...withRef.map((l, i) => ({ label: `reference ${l.label}`, stroke: colors[i], width: 1, dash: [4, 4] })),
        ],
      },
      [[], ...lines.map(() => []), ...withRef.map(() => [])],
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
    const rows = history.filter(shown);
    plot.current?.setData([
      rows.map((p) => p.frame_time_s),
      ...lines.map((l) => rows.map((p) => l.value(p) ?? null)),
      ...withRef.map((l) => rows.map((p) => l.reference?.(p) ?? null)),
    ] as uPlot.AlignedData);
  }, [history]);
  return <div ref={el} data-testid={testid} />;
}

const hasPose = (p: Pose) => p.ok;
const hasState = (p: Pose) => p.angular_rate_deg_s != null;

export function TimeSeries({ history }: { history: Pose[] }) {
  return (
    <section class="card">
      <h2>Pose over time</h2>
      <Chart history={history} lines={["x_mm", "y_mm"].map((k) => poseLine(k as Key))} unit="mm" shown={hasPose} />
      <Chart history={history} lines={[poseLine("z_mm")]} unit="mm" shown={hasPose} />
      <Chart history={history} lines={["pitch_deg", "yaw_deg", "roll_deg"].map((k) => poseLine(k as Key))} unit="deg" shown={hasPose} />
      <Chart history={history} lines={[rateLine(0, "x"), rateLine(1, "y"), rateLine(2, "z")]}
        unit="deg/s" shown={hasState} testid="rate-chart" />
    </section>
  );
}
