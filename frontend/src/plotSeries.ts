// What the live plots show: one compact sample per pose message (the numbers plotted,
// not the whole message, so that ten minutes of frames stay small), the series with
// their human labels and units, and the charts that group them.
import type { Pose } from "./api/client";

export type Unit = "mm" | "deg" | "deg/s";

/** Every plotted quantity, by key. */
export type SeriesKey =
  | "x" | "y" | "z" | "pitch" | "yaw" | "roll"
  | "ref_x" | "ref_y" | "ref_z" | "ref_pitch" | "ref_yaw" | "ref_roll"
  | "err_x" | "err_y" | "err_z" | "err_pitch" | "err_yaw" | "err_roll"
  | "err_position" | "err_attitude"
  | "rate_x" | "rate_y" | "rate_z";

export interface Sample {
  /** capture time, Unix seconds (the plots' time axis and the CSV's timestamps) */
  t: number;
  frame: number;
  /** the source's own frame time, s */
  frameTime: number;
  /** the lab reference the error is measured against (its label), when the source has one */
  reference: string | null;
  values: Partial<Record<SeriesKey, number>>;
}

export interface SeriesDef {
  key: SeriesKey;
  name: string;
  unit: Unit;
  /** a reference line: drawn dashed in the colour of the line it goes with */
  dashed?: boolean;
}

/** The legend's and the CSV header's text for a series: "x (mm)", "pitch (deg)". */
export const legendLabel = (s: Pick<SeriesDef, "name" | "unit">): string => `${s.name} (${s.unit})`;

/** An angle difference in (-180, 180] deg: yaw 179 minus yaw -179 is -2, not 358. */
export function wrapDeg(d: number): number {
  const w = (((d + 180) % 360) + 360) % 360 - 180;
  return w === -180 ? 180 : w;
}

const POSITION = ["x", "y", "z"] as const;
const ATTITUDE = ["pitch", "yaw", "roll"] as const;

const num = (v: number | null | undefined): v is number => typeof v === "number" && Number.isFinite(v);

/** The plotted numbers of one pose message: the pose (when there is one), the lab
 * reference and the pose minus it (per axis; angles wrapped), the server's position and
 * attitude error, and the angular rate of the relative-state filter. */
export function sampleOf(p: Pose): Sample {
  const values: Partial<Record<SeriesKey, number>> = {};
  const ref = p.reference ?? null;
  for (const a of POSITION) {
    const v = p.ok ? p[`${a}_mm`] : null;
    if (num(v)) values[a] = v;
    if (ref) values[`ref_${a}`] = ref[`${a}_mm`];
    if (ref && num(v)) values[`err_${a}`] = v - ref[`${a}_mm`];
  }
  for (const a of ATTITUDE) {
    const v = p.ok ? p[`${a}_deg`] : null;
    if (num(v)) values[a] = v;
    if (ref) values[`ref_${a}`] = ref[`${a}_deg`];
    if (ref && num(v)) values[`err_${a}`] = wrapDeg(v - ref[`${a}_deg`]);
  }
  if (num(ref?.position_error_mm)) values.err_position = ref.position_error_mm;
  if (num(ref?.attitude_error_deg)) values.err_attitude = ref.attitude_error_deg;
  const rate = p.angular_rate_deg_s;
  (["rate_x", "rate_y", "rate_z"] as const).forEach((k, i) => {
    if (num(rate?.[i])) values[k] = rate[i];
  });
  return { t: p.captured_unix_s, frame: p.frame_index, frameTime: p.frame_time_s, reference: ref?.label ?? null, values };
}

export interface ChartDef {
  id: string;
  title: string;
  unit: Unit;
  series: SeriesDef[];
  /** the error charts name the reference they measure against in their title */
  againstReference?: boolean;
}

const line = (key: SeriesKey, name: string, unit: Unit, dashed = false): SeriesDef => ({ key, name, unit, dashed });

export const CHARTS: ChartDef[] = [
  { id: "xy", title: "position x, y", unit: "mm", series: [
    line("x", "x", "mm"), line("y", "y", "mm"),
    line("ref_x", "reference x", "mm", true), line("ref_y", "reference y", "mm", true)] },
  { id: "z", title: "position z (range)", unit: "mm", series: [
    line("z", "z", "mm"), line("ref_z", "reference z", "mm", true)] },
  { id: "attitude", title: "attitude", unit: "deg", series: [
    line("pitch", "pitch", "deg"), line("yaw", "yaw", "deg"), line("roll", "roll", "deg"),
    line("ref_pitch", "reference pitch", "deg", true), line("ref_yaw", "reference yaw", "deg", true),
    line("ref_roll", "reference roll", "deg", true)] },
  { id: "error-position", title: "position error", unit: "mm", againstReference: true, series: [
    line("err_x", "error x", "mm"), line("err_y", "error y", "mm"), line("err_z", "error z", "mm"),
    line("err_position", "|error|", "mm")] },
  { id: "error-attitude", title: "attitude error", unit: "deg", againstReference: true, series: [
    line("err_pitch", "error pitch", "deg"), line("err_yaw", "error yaw", "deg"), line("err_roll", "error roll", "deg"),
    line("err_attitude", "angle error", "deg")] },
  { id: "rate", title: "angular rate (camera frame)", unit: "deg/s", series: [
    line("rate_x", "rate x", "deg/s"), line("rate_y", "rate y", "deg/s"), line("rate_z", "rate z", "deg/s")] },
];

/** The title of an error chart for the references met in the shown samples: the label
 * the server gives (the nominal one says "uncalibrated"), or that there is none. */
export function referenceTitle(samples: readonly Sample[]): string {
  const labels = [...new Set(samples.map((s) => s.reference).filter((r): r is string => r !== null))];
  if (labels.length === 0) return "(no lab reference from this source)";
  return labels.length === 1 ? `vs ${labels[0]}` : `vs ${labels.length} references: ${labels.join("; ")}`;
}
