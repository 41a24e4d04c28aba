import { describe, expect, it } from "vitest";
import { fmtClock, fmtDuration } from "./format";
import { parseNumber, parseNumberList, parseSetpoint } from "./setpoint";

const yaw = { name: "yaw", unit: "deg", min_pos: -170, max_pos: 170 };

describe("parseNumber", () => {
  it("takes complete decimal numbers only", () => {
    expect(parseNumber("10")).toEqual({ value: 10 });
    expect(parseNumber(" -2.5 ")).toEqual({ value: -2.5 });
    expect(parseNumber("+.5")).toEqual({ value: 0.5 });
    expect(parseNumber("1e3")).toEqual({ value: 1000 });
    for (const bad of ["-", "1.", "1e", "abc", "1,5", "0x10", "--1", "Infinity"])
      expect(parseNumber(bad)).toEqual({ error: `"${bad}" is not a number` });
    expect(parseNumber("   ")).toEqual({ error: "empty: type a number" });
    expect(parseNumber("1e400")).toEqual({ error: '"1e400" is too large' });
  });
});

describe("parseSetpoint", () => {
  it("accepts the limits themselves and refuses beyond them, naming the axis", () => {
    expect(parseSetpoint("170", yaw)).toEqual({ value: 170 });
    expect(parseSetpoint("-170", yaw)).toEqual({ value: -170 });
    expect(parseSetpoint("170.001", yaw)).toEqual({ error: "170.001 deg is outside yaw's limits -170 .. 170" });
    expect(parseSetpoint("", yaw)).toEqual({ error: "empty: type a number" });
  });
});

describe("parseNumberList", () => {
  it("reads every item or names the one that is wrong", () => {
    expect(parseNumberList("0, 5,10")).toEqual({ values: [0, 5, 10] });
    expect(parseNumberList("0, five")).toEqual({ error: 'item "five": "five" is not a number' });
    expect(parseNumberList("five")).toEqual({ error: '"five" is not a number' });
  });
});

describe("fmtDuration", () => {
  it("says minutes and seconds, or '-' when unknown", () => {
    expect(fmtDuration(200)).toBe("3 min 20 s");
    expect(fmtDuration(45.4)).toBe("45 s");
    expect(fmtDuration(null)).toBe("-");
    expect(fmtDuration(undefined)).toBe("-");
  });
});

describe("fmtClock", () => {
  it("reads the local wall clock in 24 h, with tenths when asked", () => {
    const t = new Date(2026, 11, 6, 14, 5, 3, 250).getTime() / 1000;
    expect(fmtClock(t)).toBe("14:05:03");
    expect(fmtClock(t, 1)).toBe("14:05:03.2");
    expect(fmtClock(new Date(2026, 11, 6, 9, 0, 0).getTime() / 1000)).toBe("09:00:00");
  });
});
