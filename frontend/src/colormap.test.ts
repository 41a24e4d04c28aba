import { interpolateTurbo } from "d3-scale-chromatic";
import { describe, expect, it } from "vitest";
import { activePixels, distancePixels, grayPixels, quantile, turboCss, turboRgb } from "./colormap";
import type { RawFrame } from "./rawframe";

function frame(gray: number[], distance: number[], width = gray.length, fullScale = 0): RawFrame {
  return { frameIndex: 1, step: 1, width, height: gray.length / width, fullScale, gray: Uint16Array.from(gray), distance: Uint16Array.from(distance) };
}
const pixels = (n: number) => ({ data: new Uint8ClampedArray(4 * n) });
const rgba = (p: { data: Uint8ClampedArray }, i: number) => Array.from(p.data.slice(4 * i, 4 * i + 4));

describe("turbo", () => {
  it("has d3's turbo end points: dark at 0, dark red at 1, and clamps outside [0, 1]", () => {
    expect(turboCss(0)).toBe("rgb(35, 23, 27)");
    expect(turboCss(1)).toBe("rgb(144, 12, 0)");
    expect(turboRgb(0)).toEqual([35, 23, 27]);
    expect(turboRgb(1)).toEqual([144, 12, 0]);
    expect(turboRgb(-3)).toEqual(turboRgb(0));
    expect(turboRgb(7)).toEqual(turboRgb(1));
  });

  it("runs blue (near) through green to red (far)", () => {
    const [r1, g1, b1] = turboRgb(0.15);
    expect(b1).toBeGreaterThan(r1);
    expect(b1).toBeGreaterThan(g1);
    const [r2, g2, b2] = turboRgb(0.5);
    expect(g2).toBeGreaterThan(r2);
    expect(g2).toBeGreaterThan(b2);
    const [r3, g3, b3] = turboRgb(0.9);
    expect(r3).toBeGreaterThan(g3);
    expect(r3).toBeGreaterThan(b3);
  });

  it("its 256-entry table matches the continuous map at every entry", () => {
    for (const i of [0, 1, 64, 127, 128, 200, 254, 255]) {
      const css = interpolateTurbo(i / 255).match(/\d+/g)!.map(Number);
      expect(turboRgb(i / 255)).toEqual(css);
    }
  });
});

describe("quantile", () => {
  it("picks the q-quantile of the kept values", () => {
    const v = Uint16Array.from([0, 50, 10, 40, 20, 30, 0]);
    expect(quantile(v, 0, (x) => x > 0)).toBe(10);
    expect(quantile(v, 0.5, (x) => x > 0)).toBe(30); // 5 values: index floor(2.5) = 2 of 10..50
    expect(quantile(v, 0.999, (x) => x > 0)).toBe(50);
    expect(quantile(Uint16Array.from([0, 0]), 0.5, (x) => x > 0)).toBe(0); // nothing kept
  });
});

describe("grayPixels", () => {
  it("maps counts with gamma 0.5 up to the 99.5th percentile, opaque", () => {
    // 1000 pixels: one very bright outlier above the 99.5th percentile, which is 1600
    const gray = Array.from({ length: 1000 }, () => 1600);
    gray[0] = 0;
    gray[1] = 400; // (400 / 1600)^0.5 = 0.5 -> 127.5, stored as 128
    gray[2] = 100; // 0.25 -> 63.75 -> 64
    gray[3] = 60000; // above the top: clipped to 255
    const out = pixels(gray.length);
    grayPixels(frame(gray, gray.map(() => 0)), out);
    expect(rgba(out, 0)).toEqual([0, 0, 0, 255]);
    expect(rgba(out, 1)).toEqual([128, 128, 128, 255]);
    expect(rgba(out, 2)).toEqual([64, 64, 64, 255]);
    expect(rgba(out, 3)).toEqual([255, 255, 255, 255]);
    expect(rgba(out, 4)).toEqual([255, 255, 255, 255]);
  });

  it("maps counts with gamma 0.5 up to the camera's full scale when the frame states one", () => {
    // an Azure Kinect's 16-bit IR: full scale 65535, counts far above a 12-bit camera's
    const gray = [0, 16384, 4096, 65535, 4095];
    const out = pixels(gray.length);
    grayPixels(frame(gray, gray.map(() => 0), gray.length, 65535), out);
    expect(rgba(out, 0)).toEqual([0, 0, 0, 255]);
    expect(rgba(out, 1)).toEqual([128, 128, 128, 255]); // (16384 / 65535)^0.5 = 0.500004 -> 128
    expect(rgba(out, 2)).toEqual([64, 64, 64, 255]); // 0.250002 -> 63.75 -> 64
    expect(rgba(out, 3)).toEqual([255, 255, 255, 255]); // full scale: white
    expect(rgba(out, 4)).toEqual([64, 64, 64, 255]); // a 12-bit camera's white is dark here
    // the TOFcam-660's 4095: its own full scale is white
    const tof = pixels(2);
    grayPixels(frame([4095, 1024], [0, 0], 2, 4095), tof);
    expect(rgba(tof, 0)).toEqual([255, 255, 255, 255]);
    expect(rgba(tof, 1)).toEqual([128, 128, 128, 255]); // (1024 / 4095)^0.5 = 0.50006 -> 127.5
  });

  it("draws an all-black frame black (no division by zero)", () => {
    const out = pixels(4);
    grayPixels(frame([0, 0, 0, 0], [0, 0, 0, 0]), out);
    expect(Array.from(out.data)).toEqual([0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 255, 0, 0, 0, 255]);
  });
});

describe("distancePixels", () => {
  it("maps the 2nd..98th percentile of valid distances onto turbo, invalid pixels black", () => {
    // valid distances 1000..1099 mm (100 values) and 10 invalid ones
    const distance = [...Array.from({ length: 100 }, (_, i) => 1000 + i), ...Array.from({ length: 10 }, () => 0)];
    const out = pixels(distance.length);
    const [lo, hi] = distancePixels(frame(distance.map(() => 1), distance), out);
    expect([lo, hi]).toEqual([1002, 1098]); // sample[floor(0.02 * 100)], sample[floor(0.98 * 100)]
    expect(rgba(out, 2)).toEqual([...turboRgb(0), 255]); // at lo: the near (blue-black) end
    expect(rgba(out, 0)).toEqual([...turboRgb(0), 255]); // below lo: clamped
    expect(rgba(out, 98)).toEqual([...turboRgb(1), 255]); // at hi: the far (red) end
    expect(rgba(out, 99)).toEqual([...turboRgb(1), 255]);
    expect(rgba(out, 50)).toEqual([...turboRgb((1050 - 1002) / 96), 255]);
    expect(rgba(out, 105)).toEqual([0, 0, 0, 255]); // invalid
  });

  it("keeps a one-value frame drawable (the range is at least 1 mm)", () => {
    const out = pixels(3);
    expect(distancePixels(frame([1, 1, 1], [500, 500, 0]), out)).toEqual([500, 501]);
    expect(rgba(out, 0)).toEqual([...turboRgb(0), 255]);
  });
});

describe("activePixels", () => {
  it("marks gray >= threshold cyan and translucent, the rest transparent, and counts them", () => {
    const out = pixels(4);
    expect(activePixels(frame([99, 100, 101, 0], [0, 0, 0, 0]), 100, out)).toBe(2);
    expect(rgba(out, 0)).toEqual([0, 230, 255, 0]);
    expect(rgba(out, 1)).toEqual([0, 230, 255, 150]);
    expect(rgba(out, 2)).toEqual([0, 230, 255, 150]);
    expect(rgba(out, 3)).toEqual([0, 230, 255, 0]);
  });
});
