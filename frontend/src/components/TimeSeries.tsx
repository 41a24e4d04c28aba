// The live plots (uPlot): the pose, the lab reference (dashed), the pose minus the
// reference and the angular rate over a chosen time window; pause freezes what is shown
// while the stream goes on, drag or wheel on a plot zooms all of them (double-click or
// "reset zoom" undoes it), and CSV exports exactly the series and samples shown.
import { useEffect, useMemo, useRef, useState } from "preact/hooks";
import uPlot from "uplot";
import "uplot/dist/uPlot.min.css";
import { fmtClock } from "../format";
import { csvFileName, csvText, exportedSeries } from "../plotCsv";
import { CHARTS, legendLabel, referenceTitle, type ChartDef, type Sample, type SeriesKey } from "../plotSeries";
import { columns, inRange, windowLabel, windowRange, WINDOWS_S, zoomAt, type Range, type SampleBuffer } from "../plotWindow";

const REDRAW_MS = 250;
const COLORS = ["#1f77b4", "#d62728", "#2ca02c", "#222"];
const WHEEL_STEP = 0.8;
const TIME_STEPS_S = [0.1, 0.2, 0.5, 1, 2, 5, 10, 15, 30, 60, 120, 300, 600, 900, 1800, 3600];

interface ChartProps {
  def: ChartDef;
  shown: Sample[];
  range: Range | null;
  height: number;
  onZoom: (r: Range) => void;
  onWheel: (at: number, factor: number) => void;
  onReset: () => void;
  onToggle: (key: SeriesKey, show: boolean) => void;
}

function Chart({ def, shown, range, height, onZoom, onWheel, onReset, onToggle }: ChartProps) {
  const el = useRef<HTMLDivElement>(null);
  const plot = useRef<uPlot | null>(null);
  // uPlot's hooks are set once: they call the newest callbacks through this ref
  const calls = useRef({ onZoom, onWheel, onReset, onToggle });
  calls.current = { onZoom, onWheel, onReset, onToggle };
  useEffect(() => {
    const box = el.current;
    if (!box) return;
    let solid = 0;
    let dashed = 0;
    const u = new uPlot(
      {
        width: box.clientWidth || 300, height,
        scales: { x: { time: true } },
        axes: [
          // 24 h wall clock, tenths of a second once zoomed below a second a tick; steps of
          // 2 s as well (uPlot's own go from 1 s to 5 s: a 3 s zoom would get no tick)
          { size: 28, font: "10px system-ui, sans-serif", incrs: TIME_STEPS_S,
            space: (_u, _i, min, max, dim) => ((max - min) * 52 / dim < 1 ? 64 : 52),
            values: (_u, ticks, _i, _space, incr) => ticks.map((t) => fmtClock(t, incr < 1 ? 1 : 0)) },
          // as wide as its longest tick label (a range near 7 m reads "6,999.6" mm, wider
          // than a fixed width leaves beside the unit's label)
          { label: def.unit, size: valueAxisSize, labelSize: 14 },
        ],
        legend: { live: true },
        cursor: {
          sync: { key: "tofpose-plots", setSeries: false },
          drag: { x: true, y: false, setScale: false },
          bind: { dblclick: () => () => { calls.current.onReset(); return null; } },
        },
        series: [
          { label: "time", value: (_u, v) => (v == null ? "-" : fmtClock(v)) },
          ...def.series.map((s) => ({
            label: legendLabel(s),
            stroke: COLORS[s.dashed ? dashed++ : solid++],
            width: s.dashed ? 1 : 1.5,
            dash: s.dashed ? [4, 4] : undefined,
            value: (_u: uPlot, v: number | null) => (v == null ? "-" : v.toFixed(def.unit === "mm" ? 2 : 3)),
          })),
        ],
        hooks: {
          setSelect: [(self) => {
            if (self.select.width < 3) return;
            const a = self.posToVal(self.select.left, "x");
            const b = self.posToVal(self.select.left + self.select.width, "x");
            self.setSelect({ left: 0, top: 0, width: 0, height: 0 }, false);
            calls.current.onZoom([a, b]);
          }],
          setSeries: [(self, i, opts) => {
            if (i !== null && i > 0 && opts.show !== undefined) calls.current.onToggle(def.series[i - 1].key, opts.show);
          }],
        },
      },
      columns([], def.series.map((s) => s.key)) as uPlot.AlignedData,
      box,
    );
    const wheel = (e: WheelEvent) => {
      e.preventDefault();
      const left = e.clientX - u.over.getBoundingClientRect().left;
      calls.current.onWheel(u.posToVal(left, "x"), e.deltaY < 0 ? WHEEL_STEP : 1 / WHEEL_STEP);
    };
    u.over.addEventListener("wheel", wheel, { passive: false });
    const resize = new ResizeObserver(() => u.setSize({ width: box.clientWidth, height }));
    resize.observe(box);
    plot.current = u;
    return () => {
      resize.disconnect();
      u.destroy();
    };
  }, []);
  useEffect(() => {
    const u = plot.current;
    if (!u) return;
    u.setData(columns(shown, def.series.map((s) => s.key)) as uPlot.AlignedData, false);
    if (range) u.setScale("x", { min: range[0], max: range[1] });
  }, [shown, range]);
  const title = def.againstReference ? `${def.title} ${referenceTitle(shown)}` : def.title;
  const tip = def.againstReference ? `${title}: the pose minus the lab reference, per axis; |error| and angle error as the server computes them` : title;
  return (
    <figure class="chart" data-testid={`chart-${def.id}`}>
      <figcaption data-testid={`chart-${def.id}-title`} title={tip}>{title}</figcaption>
      <div ref={el} />
    </figure>
  );
}

/** The chart height that puts two rows of charts on the first screen, from 768 px up. */
const chartHeight = () => Math.max(100, Math.min(220, Math.round((window.innerHeight - 768) / 2 + 114)));

/** The value axis' width (px): its ticks, its gap and its longest tick label as drawn in
 * the axis' font, rounded up to 8 px (a plot does not twitch as its labels change by a
 * digit) and at least 40 px (uPlot's recipe for a dynamic axis size; 52 px was fixed
 * before, and a label of seven digits ran under the unit's). */
export function valueAxisSize(u: uPlot, values: string[] | null, axisIdx: number, cycleNum: number): number {
  const axis = u.axes[axisIdx];
  if (cycleNum > 1) return (axis as { _size?: number })._size ?? 52;
  const longest = (values ?? []).reduce((a, v) => (v.length > a.length ? v : a), "");
  const tick = (axis.ticks?.size ?? 10) + (axis.gap ?? 5);
  if (!longest) return Math.max(40, tick);
  u.ctx.font = (axis.font as unknown as [string])?.[0] ?? "12px system-ui, sans-serif";
  const px = tick + u.ctx.measureText(longest).width / uPlot.pxRatio + 4;
  return Math.max(40, 8 * Math.ceil(px / 8));
}

export function TimeSeries({ samples }: { samples: SampleBuffer }) {
  const [windowS, setWindowS] = useState(30);
  const [live, setLive] = useState<Sample[]>([]);
  const [frozen, setFrozen] = useState<Sample[] | null>(null);
  const [zoom, setZoom] = useState<Range | null>(null);
  const hidden = useRef(new Set<SeriesKey>());
  const [height] = useState(chartHeight);
  // the live data is taken from the store at most 4 times a second: plenty for a plot,
  // and the page keeps its time for the images at 30 Hz
  useEffect(() => {
    if (frozen) return;
    const take = () => setLive(samples.snapshot());
    take();
    const timer = window.setInterval(take, REDRAW_MS);
    return () => window.clearInterval(timer);
  }, [frozen, samples]);

  const all = frozen ?? live;
  const range = useMemo(() => zoom ?? windowRange(all, windowS), [zoom, all, windowS]);
  const shown = useMemo(() => (range ? inRange(all, range) : []), [all, range]);
  const limit: Range | null = all.length ? [all[0].t, all[all.length - 1].t] : null;

  const pause = () => setFrozen(samples.snapshot());
  const resume = () => {
    setZoom(null);
    setFrozen(null);
  };
  const zoomTo = (r: Range) => {
    if (!frozen) setFrozen(all); // a zoom freezes the data, or the next frame would move it
    setZoom(r[1] > r[0] ? r : null);
  };
  const wheel = (at: number, factor: number) => {
    if (range && limit) zoomTo(zoomAt(range, at, factor, [Math.min(limit[0], range[0]), Math.max(limit[1], range[1])]));
  };
  const chooseWindow = (s: number) => {
    setWindowS(s);
    setZoom(null);
  };
  const exportCsv = () => {
    const series = exportedSeries(CHARTS.flatMap((c) => c.series), shown, hidden.current);
    const url = URL.createObjectURL(new Blob([csvText(shown, series)], { type: "text/csv" }));
    const a = document.createElement("a");
    a.href = url;
    a.download = csvFileName(shown);
    a.click();
    window.setTimeout(() => URL.revokeObjectURL(url), 10_000);
  };
  const toggle = (key: SeriesKey, show: boolean) => {
    if (show) hidden.current.delete(key);
    else hidden.current.add(key);
  };

  return (
    <section class="card plots" data-testid="plots">
      <div class="plots-bar">
        <h2>Plots</h2>
        <span class="segmented" role="group" aria-label="time window">
          {WINDOWS_S.map((s) => (
            <button key={s} aria-pressed={s === windowS && !zoom} data-testid={`plot-window-${s}`}
              onClick={() => chooseWindow(s)}>{windowLabel(s)}</button>
          ))}
        </span>
        {frozen ? (
          <button data-testid="plot-resume" onClick={resume} title="show the live data again">▶ resume</button>
        ) : (
          <button data-testid="plot-pause" onClick={pause} title="freeze what is shown; the stream goes on">❚❚ pause</button>
        )}
        <button data-testid="plot-reset-zoom" disabled={!zoom} onClick={() => setZoom(null)}
          title="back to the whole window (or double-click a plot)">reset zoom</button>
        <button data-testid="plot-csv" disabled={shown.length === 0} onClick={exportCsv}
          title="the shown series over the shown time, one row per sample">CSV</button>
        <span class="small" data-testid="plot-status">
          {range ? `${fmtClock(range[0])} – ${fmtClock(range[1])}` : "no frame yet"}
          {frozen && ", paused (the stream goes on)"}
          {zoom && ", zoomed"}
          {!zoom && " · drag or wheel to zoom"}
        </span>
      </div>
      <div class="charts">
        {CHARTS.map((def) => (
          <Chart key={def.id} def={def} shown={shown} range={range} height={height}
            onZoom={zoomTo} onWheel={wheel} onReset={() => setZoom(null)} onToggle={toggle} />
        ))}
      </div>
    </section>
  );
}
