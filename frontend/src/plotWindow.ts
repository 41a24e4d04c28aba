// The time window of the live plots: a bounded buffer of samples, the samples inside a
// time range, the columns uPlot draws, and the range after a wheel zoom.
import type { Sample, SeriesKey } from "./plotSeries";

export const WINDOWS_S = [10, 30, 120, 600] as const;

/** "10 s", "2 min" */
export const windowLabel = (s: number): string => (s < 60 ? `${s} s` : `${s / 60} min`);

/** [start, end] in Unix seconds */
export type Range = [number, number];

/** Samples in capture order, the oldest dropped once they are more than `keepS` older
 * than the newest (the longest window) or more than `maxSamples` are kept. */
export class SampleBuffer {
  private items: Sample[] = [];
  private start = 0; // index of the oldest kept sample: dropped in chunks, not one shift per frame
  version = 0;

  constructor(readonly keepS: number = WINDOWS_S[WINDOWS_S.length - 1], readonly maxSamples = 40_000) {}

  push(s: Sample): void {
    const last = this.items[this.items.length - 1];
    if (last && this.items.length > this.start && s.t < last.t) return; // out of order: the time axis only grows
    this.items.push(s);
    while (this.start < this.items.length && (s.t - this.items[this.start].t > this.keepS ||
      this.items.length - this.start > this.maxSamples)) this.start++;
    if (this.start > 4096) {
      this.items = this.items.slice(this.start);
      this.start = 0;
    }
    this.version++;
  }

  /** A copy of the kept samples, oldest first (a paused plot keeps one). */
  snapshot(): Sample[] {
    return this.items.slice(this.start);
  }

  get length(): number {
    return this.items.length - this.start;
  }
}

/** Index of the first sample with t >= value (samples sorted by t). */
function lowerBound(samples: readonly Sample[], value: number): number {
  let lo = 0;
  let hi = samples.length;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (samples[mid].t < value) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

/** The samples with start <= t <= end. */
export function inRange(samples: readonly Sample[], [start, end]: Range): Sample[] {
  const i = lowerBound(samples, start);
  let j = i;
  while (j < samples.length && samples[j].t <= end) j++;
  return samples.slice(i, j);
}

/** The last `windowS` seconds up to the newest sample (or up to `end`). */
export function windowRange(samples: readonly Sample[], windowS: number, end?: number): Range | null {
  const last = end ?? samples[samples.length - 1]?.t;
  return last === undefined ? null : [last - windowS, last];
}

/** uPlot's columns: the times, then each series (null where a sample has no value). */
export function columns(samples: readonly Sample[], keys: readonly SeriesKey[]): (number | null)[][] {
  return [samples.map((s) => s.t), ...keys.map((k) => samples.map((s) => s.values[k] ?? null))];
}

/** The range after a wheel step at `at` (kept where it is on screen): `factor` < 1 zooms
 * in, > 1 out; never wider than `limit`. */
export function zoomAt([start, end]: Range, at: number, factor: number, limit: Range): Range {
  const f = Math.min(Math.max(factor, 0.01), 100);
  let s = at - (at - start) * f;
  let e = at + (end - at) * f;
  const maxWidth = limit[1] - limit[0];
  if (e - s >= maxWidth) return limit;
  if (s < limit[0]) [s, e] = [limit[0], limit[0] + (e - s)];
  if (e > limit[1]) [s, e] = [limit[1] - (e - s), limit[1]];
  return [s, e];
}
