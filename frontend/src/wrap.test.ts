import { describe, expect, it } from "vitest";
import { wrapNotice } from "./wrap";

describe("wrapNotice", () => {
  it("is silent for distances taken as measured", () => {
    expect(wrapNotice({ distances_read_about_mm: null })).toBeNull();
    expect(wrapNotice({})).toBeNull();
    expect(wrapNotice(null)).toBeNull();
  });
  it("names the range the distances were read about, in metres", () => {
    const text = wrapNotice({ distances_read_about_mm: 8012.4 });
    expect(text).toContain("read about 8.0 m");
    expect(text).toContain("wrap");
  });
});
