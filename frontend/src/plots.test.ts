import { describe, expect, it } from "vitest";
import type { Pose } from "./api/client";
import { csvFileName, csvText, exportedSeries } from "./plotCsv";
import { CHARTS, legendLabel, referenceTitle, sampleOf, wrapDeg, type Sample } from "./plotSeries";
import { columns, inRange, SampleBuffer, windowLabel, windowRange, zoomAt } from "./plotWindow";

const NOMINAL = "nominal lab geometry (uncalibrated)";

/** A pose message with only what the plots read. */
function pose(over: Partial<Pose> = {}): Pose {
  return {
    ok: true, frame_index: 7, frame_time_s: 0.35, captured_unix_s: 1_765_000_000.25,
    x_mm: 7.25, y_mm: 8, z_mm: 1999.5, pitch_deg: -0.2, yaw_deg: 179.5, roll_deg: 0.1,
    reference: { label: NOMINAL, x_mm: 0, y_mm: -1, z_mm: 2000, pitch_deg: 0, yaw_deg: -179.5, roll_deg: 0,
      position_error_mm: 10.8, attitude_error_deg: 0.34 },
    angular_rate_deg_s: [0.5, -1, 2],
    ...over,
  } as Pose;
}

const sample = (t: number, values: Sample["values"] = { x: t }, reference: string | null = null): Sample =>
  ({ t, frame: Math.round(t), frameTime: t, reference, values });

describe("legendLabel", () => {
  it("reads as words with the unit, never as a field name", () => {
    expect(legendLabel({ name: "x", unit: "mm" })).toBe("x (mm)");
    expect(legendLabel({ name: "pitch", unit: "deg" })).toBe("pitch (deg)");
    const labels = CHARTS.flatMap((c) => c.series.map(legendLabel));
    expect(labels).toContain("reference yaw (deg)");
    expect(labels).toContain("rate z (deg/s)");
    for (const l of labels) expect(l).not.toMatch(/_(mm|deg)/);
    expect(new Set(labels).size).toBe(labels.length);
  });
});

describe("sampleOf", () => {
  it("takes the pose, the reference and the pose minus the reference, angles wrapped", () => {
    const s = sampleOf(pose());
    expect(s.t).toBe(1_765_000_000.25);
    expect(s.frame).toBe(7);
    expect(s.reference).toBe(NOMINAL);
    expect(s.values.x).toBe(7.25);
    expect(s.values.ref_y).toBe(-1);
    expect(s.values.err_x).toBeCloseTo(7.25);
    expect(s.values.err_y).toBeCloseTo(9);
    expect(s.values.err_z).toBeCloseTo(-0.5);
    expect(s.values.err_yaw).toBeCloseTo(-1); // 179.5 - (-179.5) is -1 deg, not 359
    expect(s.values.err_position).toBe(10.8);
    expect(s.values.err_attitude).toBe(0.34);
    expect(s.values.rate_z).toBe(2);
  });

  it("has no pose or error values for a frame without a pose, but keeps the reference and rate", () => {
    const s = sampleOf(pose({ ok: false, x_mm: null, y_mm: null, z_mm: null, pitch_deg: null, yaw_deg: null, roll_deg: null }));
    expect(s.values.x).toBeUndefined();
    expect(s.values.err_x).toBeUndefined();
    expect(s.values.ref_z).toBe(2000);
    expect(s.values.rate_x).toBe(0.5);
  });

  it("has no reference or error without a lab reference", () => {
    const s = sampleOf(pose({ reference: null, angular_rate_deg_s: null }));
    expect(s.reference).toBeNull();
    expect(Object.keys(s.values).sort()).toEqual(["pitch", "roll", "x", "y", "yaw", "z"]);
  });
});

describe("wrapDeg", () => {
  it("maps an angle difference into (-180, 180]", () => {
    expect([0, 10, -10, 190, -190, 360, 540, -180, 180].map(wrapDeg)).toEqual([0, 10, -10, -170, 170, 0, 180, 180, 180]);
  });
});

describe("referenceTitle", () => {
  it("names the reference, and says so when it is uncalibrated or when there is none", () => {
    expect(referenceTitle([sample(1, {}, NOMINAL), sample(2, {}, NOMINAL)])).toBe(`vs ${NOMINAL}`);
    expect(referenceTitle([sample(1), sample(2)])).toBe("(no lab reference from this source)");
    expect(referenceTitle([sample(1, {}, NOMINAL), sample(2, {}, "calibration 3 ('bench')")]))
      .toBe(`vs 2 references: ${NOMINAL}; calibration 3 ('bench')`);
  });
});

describe("SampleBuffer", () => {
  it("keeps the last keepS seconds, in time order", () => {
    const b = new SampleBuffer(10);
    for (let t = 0; t <= 30; t += 0.5) b.push(sample(t));
    const kept = b.snapshot();
    expect(kept[0].t).toBe(20);
    expect(kept[kept.length - 1].t).toBe(30);
    expect(b.length).toBe(21);
    b.push(sample(29)); // older than the newest: refused
    expect(b.snapshot()[b.length - 1].t).toBe(30);
  });

  it("is bounded in count and survives its compaction", () => {
    const b = new SampleBuffer(1e9, 100);
    for (let i = 0; i < 10_000; i++) b.push(sample(i));
    expect(b.length).toBe(100);
    expect(b.snapshot().map((s) => s.t)).toEqual(Array.from({ length: 100 }, (_, i) => 9900 + i));
    expect(b.version).toBe(10_000);
  });

  it("a snapshot does not change when samples arrive (what pause shows)", () => {
    const b = new SampleBuffer(10);
    b.push(sample(1));
    const frozen = b.snapshot();
    b.push(sample(2));
    expect(frozen.map((s) => s.t)).toEqual([1]);
  });
});

describe("windows", () => {
  const samples = Array.from({ length: 61 }, (_, i) => sample(100 + i * 0.5)); // 100 .. 130 s

  it("labels the choices", () => {
    expect([10, 30, 120, 600].map(windowLabel)).toEqual(["10 s", "30 s", "2 min", "10 min"]);
  });

  it("ends at the newest sample, or at a given end (paused)", () => {
    expect(windowRange(samples, 10)).toEqual([120, 130]);
    expect(windowRange(samples, 10, 115)).toEqual([105, 115]);
    expect(windowRange([], 10)).toBeNull();
  });

  it("selects the samples inside the range, ends included", () => {
    const shown = inRange(samples, [120, 125]);
    expect(shown.map((s) => s.t)).toEqual([120, 120.5, 121, 121.5, 122, 122.5, 123, 123.5, 124, 124.5, 125]);
    expect(inRange(samples, [200, 300])).toEqual([]);
    expect(inRange(samples, [0, 100]).map((s) => s.t)).toEqual([100]);
  });

  it("gives uPlot's columns with null for missing values", () => {
    const c = columns([sample(1, { x: 5 }), sample(2, { y: 6 })], ["x", "y"]);
    expect(c).toEqual([[1, 2], [5, null], [null, 6]]);
  });
});

describe("zoomAt", () => {
  const limit: [number, number] = [0, 100];
  it("zooms in around the cursor, keeping it in place", () => {
    expect(zoomAt([0, 100], 50, 0.5, limit)).toEqual([25, 75]);
    expect(zoomAt([0, 100], 0, 0.5, limit)).toEqual([0, 50]);
    expect(zoomAt([20, 40], 30, 0.5, limit)).toEqual([25, 35]);
  });

  it("zooms out no further than the data and stays inside it", () => {
    expect(zoomAt([25, 75], 50, 4, limit)).toEqual([0, 100]);
    expect(zoomAt([80, 100], 95, 1.5, limit)).toEqual([70, 100]);
  });
});

describe("csvText", () => {
  const series = CHARTS.find((c) => c.id === "xy")!.series.slice(0, 2); // x, y
  it("has a header with units and one row per sample with timestamps", () => {
    const text = csvText([sample(1_765_000_000.25, { x: 1.5, y: -2 }), sample(1_765_000_000.3, { x: 1.25 })], series);
    expect(text.split("\n")).toEqual([
      "capture time (UTC),capture time (Unix s),frame,frame time (s),x (mm),y (mm)",
      "2025-12-06T05:46:40.250Z,1765000000.250000,1765000000,1765000000.25,1.5,-2",
      "2025-12-06T05:46:40.300Z,1765000000.300000,1765000000,1765000000.3,1.25,",
      "",
    ]);
  });

  it("leaves out samples with none of the shown series", () => {
    const rows = csvText([sample(1, { x: 1 }), sample(2, { rate_x: 3 }), sample(3, { y: 2 })], series).trim().split("\n");
    expect(rows.length).toBe(3);
    expect(rows[2].endsWith(",,2")).toBe(true);
  });

  it("quotes a label with a comma", () => {
    const text = csvText([], [{ key: "x", name: "x, lab", unit: "mm" }]);
    expect(text).toBe('capture time (UTC),capture time (Unix s),frame,frame time (s),"x, lab (mm)"\n');
  });

  it("exports the series shown: not hidden, with a value in the shown samples", () => {
    const all = CHARTS.flatMap((c) => c.series);
    const shown = [sample(1, { x: 1, ref_x: 0 }), sample(2, { y: 2, rate_z: 1 })];
    expect(exportedSeries(all, shown, new Set()).map((d) => d.key)).toEqual(["x", "y", "ref_x", "rate_z"]);
    expect(exportedSeries(all, shown, new Set(["ref_x", "rate_z"])).map((d) => d.key)).toEqual(["x", "y"]);
    expect(exportedSeries(all, [], new Set())).toEqual([]);
  });

  it("names the file after the first sample", () => {
    expect(csvFileName([sample(1_765_000_000.25)])).toBe("tofpose-plots-2025-12-06T05-46-40Z.csv");
  });
});
