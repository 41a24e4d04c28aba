import { describe, expect, it } from "vitest";
import { droppedLine, latencyLine, latencyOf } from "./latency";

const message = {
  type: "pose",
  dropped: 2,
  capture_to_sent_ms: 41.7,
  latency: {
    capture_to_pose: { median_ms: 30.2, p95_ms: 44.9, n: 100 },
    capture_to_sent: { median_ms: 31.6, p95_ms: 47.5, n: 100 },
    dropped_total: { camera: 0, pipeline: 3, clients: 5 },
    window_s: 10,
  },
};

describe("latency readout", () => {
  it("formats the server's numbers", () => {
    const l = latencyOf(message)!;
    expect(latencyLine(l)).toBe("latency 32 ms median / 48 ms p95");
    expect(droppedLine(l)).toBe("dropped: camera 0, pipeline 3, this client 2");
    expect(l.captureToSentMs).toBe(41.7);
  });
  it("says n/a for a camera without a frame counter and dashes without frames", () => {
    const l = latencyOf({
      ...message,
      latency: { ...message.latency, capture_to_sent: { median_ms: null, p95_ms: null, n: 0 }, dropped_total: { camera: null, pipeline: 0, clients: 0 } },
    })!;
    expect(latencyLine(l)).toBe("latency – median / – p95");
    expect(droppedLine(l)).toBe("dropped: camera n/a, pipeline 0, this client 2");
  });
  it("is null for a message without statistics", () => {
    expect(latencyOf({ dropped: 0 })).toBeNull();
  });
});
