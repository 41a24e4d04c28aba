// The raw frames' colour maps (RGBA pixels, drawn into canvases by LiveView): gray with
// gamma 0.5, distance in turbo (near = blue, far = red, black = invalid), and the active
// pixel set as a translucent mask.
import { interpolateTurbo } from "d3-scale-chromatic";
import type { RawFrame } from "./rawframe";

/** Where the pixels go: an ImageData, or anything with its RGBA bytes (tests). */
export type Pixels = { data: Uint8ClampedArray };

/** The q-quantile of the values selected by keep, from a subsample (cheap, per frame). */
export function quantile(values: Uint16Array, q: number, keep: (x: number) => boolean): number {
  const sample: number[] = [];
  const stride = Math.max(1, Math.floor(values.length / 4000));
  for (let i = 0; i < values.length; i += stride) if (keep(values[i])) sample.push(values[i]);
  if (!sample.length) return 0;
  sample.sort((a, b) => a - b);
  return sample[Math.min(sample.length - 1, Math.floor(q * sample.length))];
}

const TURBO: Uint8ClampedArray = (() => {
  const lut = new Uint8ClampedArray(256 * 3);
  for (let i = 0; i < 256; i++) {
    const m = interpolateTurbo(i / 255).match(/\d+/g)!;
    lut.set([+m[0], +m[1], +m[2]], 3 * i);
  }
  return lut;
})();

/** Turbo at t in [0, 1] (clamped) from the 256-entry table the images use, as [r, g, b]. */
export function turboRgb(t: number): [number, number, number] {
  const k = 3 * Math.round(255 * Math.min(1, Math.max(0, t)));
  return [TURBO[k], TURBO[k + 1], TURBO[k + 2]];
}

/** Turbo at t as a CSS colour (the colour bar). */
export function turboCss(t: number): string {
  return interpolateTurbo(t);
}

/** The count the gray image's white stands for: the camera's full scale (4095 for the
 * TOFcam-660, 65535 for an Azure Kinect's IR), or the 99.5th percentile when the frame
 * does not state one. */
export function grayTop(f: RawFrame): number {
  return f.fullScale > 0 ? f.fullScale : Math.max(quantile(f.gray, 0.995, () => true), 1);
}

/** Gray image, gamma 0.5 up to ``grayTop``. */
export function grayPixels(f: RawFrame, out: Pixels): void {
  const top = grayTop(f);
  const d = out.data;
  for (let i = 0; i < f.gray.length; i++) {
    const g = Math.min(255, Math.sqrt(f.gray[i] / top) * 255);
    d[4 * i] = d[4 * i + 1] = d[4 * i + 2] = g;
    d[4 * i + 3] = 255;
  }
}

/** Distance image, turbo between the 2nd and 98th percentile of valid pixels (near =
 * blue), black where invalid; returns the range mapped, in mm. */
export function distancePixels(f: RawFrame, out: Pixels): [number, number] {
  const valid = (x: number) => x > 0;
  const lo = quantile(f.distance, 0.02, valid);
  const hi = Math.max(quantile(f.distance, 0.98, valid), lo + 1);
  const d = out.data;
  for (let i = 0; i < f.distance.length; i++) {
    const x = f.distance[i];
    if (x === 0) {
      d[4 * i] = d[4 * i + 1] = d[4 * i + 2] = 0;
    } else {
      const k = 3 * Math.round(255 * Math.min(1, Math.max(0, (x - lo) / (hi - lo))));
      d[4 * i] = TURBO[k];
      d[4 * i + 1] = TURBO[k + 1];
      d[4 * i + 2] = TURBO[k + 2];
    }
    d[4 * i + 3] = 255;
  }
  return [lo, hi];
}

/** The active pixel set A (gray >= I_t) as a translucent cyan mask; returns its size. */
export function activePixels(f: RawFrame, thresholdCounts: number, out: Pixels): number {
  const d = out.data;
  let n = 0;
  for (let i = 0; i < f.gray.length; i++) {
    const on = f.gray[i] >= thresholdCounts;
    if (on) n++;
    d[4 * i] = 0;
    d[4 * i + 1] = 230;
    d[4 * i + 2] = 255;
    d[4 * i + 3] = on ? 150 : 0;
  }
  return n;
}
