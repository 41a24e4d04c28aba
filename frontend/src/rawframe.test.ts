import { describe, expect, it } from "vitest";
import fixture from "./fixtures/raw-frame.json";
import { HEADER_BYTES, parseRawFrame } from "./rawframe";

function fromHex(hex: string): ArrayBuffer {
  const bytes = new Uint8Array(hex.length / 2);
  for (let i = 0; i < bytes.length; i++) bytes[i] = parseInt(hex.slice(2 * i, 2 * i + 2), 16);
  return bytes.buffer;
}

/** A message built field by field as frame_codec.py documents its layout. */
function message(width: number, height: number, gray: number[], distance: number[],
  { magic = "TOFR", version = 1, step = 1, index = 7, extra = 0, fullScale = 0 } = {}): ArrayBuffer {
  const buf = new ArrayBuffer(HEADER_BYTES + 4 * width * height + extra);
  const v = new DataView(buf);
  for (let i = 0; i < 4; i++) v.setUint8(i, magic.charCodeAt(i));
  v.setUint16(4, version, true);
  v.setUint16(6, step, true);
  v.setUint32(8, index, true);
  v.setUint16(12, width, true);
  v.setUint16(14, height, true);
  v.setUint32(16, fullScale, true);
  gray.forEach((g, i) => v.setUint16(HEADER_BYTES + 2 * i, g, true));
  distance.forEach((d, i) => v.setUint16(HEADER_BYTES + 2 * width * height + 2 * i, d, true));
  return buf;
}

describe("parseRawFrame", () => {
  it("decodes the server's encoding of a known frame (fixture from frame_codec.py)", () => {
    const f = parseRawFrame(fromHex(fixture.hex));
    expect(f.frameIndex).toBe(4000000123); // above 2^31: read unsigned
    expect(f.step).toBe(2);
    expect([f.width, f.height]).toEqual([3, 2]);
    expect(Array.from(f.gray)).toEqual([0, 1, 65535, 300, 4096, 7]);
    // 1000.4 -> 1000, NaN and 0 -> 0 (invalid), 70000 -> 65535, 1.2 -> 1, 12345.5 -> 12346
    expect(Array.from(f.distance)).toEqual([1000, 0, 0, 65535, 1, 12346]);
    expect(f.fullScale).toBe(0); // encoded without a full scale: not stated
    expect(Array.from(f.gray)).toEqual(fixture.gray);
    expect(Array.from(f.distance)).toEqual(fixture.distance_mm);
  });

  it("reads the camera's gray full scale from the header (an Azure Kinect's 65535)", () => {
    expect(parseRawFrame(message(1, 1, [9], [9], { fullScale: 65535 })).fullScale).toBe(65535);
    expect(parseRawFrame(message(1, 1, [9], [9], { fullScale: 4095 })).fullScale).toBe(4095);
  });

  it("reads rows first: pixel (row 1, column 0) of a 3 x 2 frame is the 4th value", () => {
    const f = parseRawFrame(message(3, 2, [10, 11, 12, 20, 21, 22], [1, 2, 3, 4, 5, 6], { step: 4, index: 99 }));
    expect(f.frameIndex).toBe(99);
    expect(f.step).toBe(4);
    expect(f.gray[1 * f.width + 0]).toBe(20);
    expect(f.distance[1 * f.width + 2]).toBe(6);
  });

  it("refuses a message that is not a raw frame, and one whose size does not match its header", () => {
    expect(() => parseRawFrame(message(2, 2, [], [], { magic: "PNG!" }))).toThrow(/not a raw frame \(PNG!\)/);
    expect(() => parseRawFrame(message(2, 2, [], [], { version: 2 }))).toThrow(/not a raw frame/);
    expect(() => parseRawFrame(message(2, 2, [], [], { extra: 2 }))).toThrow("raw frame of 42 bytes for 2 x 2 px");
    expect(() => parseRawFrame(new ArrayBuffer(10))).toThrow(/shorter than its header/);
  });
});
