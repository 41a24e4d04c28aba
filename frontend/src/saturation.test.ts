import { describe, expect, it } from "vitest";
import { reflectorLabel, saturationWarning } from "./saturation";

describe("saturated reflectors in the live view", () => {
  it("labels a saturated reflector so, and a clean one by its id alone", () => {
    expect(reflectorLabel({ catalog_id: 7, saturated: true })).toBe("7 saturated");
    expect(reflectorLabel({ catalog_id: 3, saturated: false })).toBe("3");
  });

  it("warns with the server's count and what to do, only when reflectors saturate", () => {
    expect(saturationWarning({ saturated_reflectors: 2 })).toBe(
      "2 reflectors saturate: lower the integration time or turn auto exposure on",
    );
    expect(saturationWarning({ saturated_reflectors: 1 })).toBe(
      "1 reflector saturates: lower the integration time or turn auto exposure on",
    );
    expect(saturationWarning({ saturated_reflectors: 0 })).toBeNull();
    expect(saturationWarning(null)).toBeNull();
  });
});
