// CSV text of exactly what the plots show: one row per sample in the shown time range,
// timestamps first, then each shown series under its label with its unit.
import { legendLabel, type Sample, type SeriesDef } from "./plotSeries";

const cell = (text: string): string => (/[",\n]/.test(text) ? `"${text.replace(/"/g, '""')}"` : text);

const number = (v: number | undefined): string => (v === undefined ? "" : String(Number(v.toFixed(6))));

export const TIME_COLUMNS = ["capture time (UTC)", "capture time (Unix s)", "frame", "frame time (s)"];

/** The CSV of `series` over `samples` (already the shown range): a sample with none of
 * these series is left out; an empty cell is a value the sample does not have. */
export function csvText(samples: readonly Sample[], series: readonly SeriesDef[]): string {
  const header = [...TIME_COLUMNS, ...series.map(legendLabel)].map(cell).join(",");
  const rows = samples
    .filter((s) => series.some((d) => s.values[d.key] !== undefined))
    .map((s) => [
      new Date(s.t * 1000).toISOString(),
      s.t.toFixed(6),
      String(s.frame),
      number(s.frameTime),
      ...series.map((d) => number(s.values[d.key])),
    ].join(","));
  return [header, ...rows].join("\n") + "\n";
}

/** The series a CSV of the shown plots carries: those not hidden in a legend that have a
 * value in the shown samples, in the charts' order. */
export function exportedSeries(all: readonly SeriesDef[], samples: readonly Sample[], hidden: ReadonlySet<string>): SeriesDef[] {
  return all.filter((d) => !hidden.has(d.key) && samples.some((s) => s.values[d.key] !== undefined));
}

/** "tofpose-plots-2026-12-06T14-05-03Z.csv", named after the first shown sample. */
export function csvFileName(samples: readonly Sample[]): string {
  const t = samples[0]?.t ?? 0;
  return `tofpose-plots-${new Date(t * 1000).toISOString().slice(0, 19).replace(/:/g, "-")}Z.csv`;
}
