// Raw frames from /ws/live (binary messages, backend/services/live/frame_codec.py): parsing.
// Their colour maps are in colormap.ts.

export type RawFrame = {
  frameIndex: number;
  step: number;
  width: number;
  height: number;
  fullScale: number; // the camera's gray full scale (counts); 0 = not stated
  gray: Uint16Array; // counts
  distance: Uint16Array; // mm, 0 = invalid
};

export const HEADER_BYTES = 24;

export function parseRawFrame(buf: ArrayBuffer): RawFrame {
  if (buf.byteLength < HEADER_BYTES) throw new Error(`raw frame of ${buf.byteLength} bytes is shorter than its header`);
  const v = new DataView(buf);
  const magic = String.fromCharCode(v.getUint8(0), v.getUint8(1), v.getUint8(2), v.getUint8(3));
  if (magic !== "TOFR" || v.getUint16(4, true) !== 1) throw new Error(`not a raw frame (${magic})`);
  const width = v.getUint16(12, true);
  const height = v.getUint16(14, true);
  const n = width * height;
  if (buf.byteLength !== HEADER_BYTES + 4 * n) throw new Error(`raw frame of ${buf.byteLength} bytes for ${width} x ${height} px`);
  return {
    frameIndex: v.getUint32(8, true),
    step: v.getUint16(6, true),
    width,
    height,
    fullScale: v.getUint32(16, true),
    gray: new Uint16Array(buf, HEADER_BYTES, n),
    distance: new Uint16Array(buf, HEADER_BYTES + 2 * n, n),
  };
}
