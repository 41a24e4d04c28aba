import { describe, expect, it } from "vitest";
import { pixelFitText } from "./pixelFit";

describe("pixelFitText", () => {
  it("is silent when the fit did not run", () => {
    expect(pixelFitText({ pixel_fit: null, timings_ms: {} })).toBeNull();
    expect(pixelFitText({ timings_ms: {} })).toBeNull();
    expect(pixelFitText(null)).toBeNull();
  });
  it("says the pose is the fit's, with its time", () => {
    const text = pixelFitText({ pixel_fit: "ok", timings_ms: { total: 1.2, "pixel fit": 17.6 } });
    expect(text).toBe("refined on the markers' pixels (18 ms): the pose and sigmas of the sensor model's fit");
  });
  it("says why the centroid pose stands", () => {
    const text = pixelFitText({ pixel_fit: "markers [7] have clipped cores", timings_ms: { "pixel fit": 9 } });
    expect(text).toContain("fell back (9 ms): the centroid pose");
    expect(text).toContain("markers [7] have clipped cores");
  });
});
