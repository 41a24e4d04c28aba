import { describe, expect, it } from "vitest";
import {
  calibrationPreset, campaignRequest, generator, INITIAL_FORM, KINDS, params, profileText, takesFrames, withKind,
  type CampaignForm,
} from "./campaignForm";

const form = (part: Partial<CampaignForm>): CampaignForm => ({ ...INITIAL_FORM, ...part });

describe("campaignRequest", () => {
  it("sends the placeholders of empty fields: a default grid is one set-point at 12 m", () => {
    expect(campaignRequest(form({ name: "g" }))).toEqual({
      body: {
        name: "g", frames_per_point: 20, record_raw: false,
        generator: { kind: "grid", yaw_deg: [0], pitch_deg: [0], roll_deg: [0], rail_mm: [12000] },
      },
    });
  });

  it("sends typed lists and numbers as numbers", () => {
    const r = campaignRequest(form({ name: "page-grid", fields: { yaw_deg: "0, 3", rail_mm: " 12500 " }, frames: "4", recordRaw: true }));
    expect(r).toEqual({
      body: {
        name: "page-grid", frames_per_point: 4, record_raw: true,
        generator: { kind: "grid", yaw_deg: [0, 3], pitch_deg: [0], roll_deg: [0], rail_mm: [12500] },
      },
    });
  });

  it("names the field and the item that is not a number, and sends nothing", () => {
    expect(campaignRequest(form({ fields: { yaw_deg: "0, x" } }))).toEqual({ error: 'yaw deg (list): item "x": "x" is not a number' });
    expect(campaignRequest(form({ fields: { pitch_deg: "0,,5" } }))).toEqual({ error: 'pitch deg (list): item "": empty: type a number' });
    expect(campaignRequest(form({ fields: { rail_mm: "1e" } }))).toEqual({ error: 'rail mm (list): "1e" is not a number' });
    expect(campaignRequest(form({ kind: "range_sweep", fields: { points: "6 points" } })))
      .toEqual({ error: 'points: "6 points" is not a number' });
    expect(campaignRequest(form({ fields: { yaw_deg: "1e999" } }))).toEqual({ error: 'yaw deg (list): "1e999" is too large' });
  });

  it("checks the frame count unless the campaign is dynamic", () => {
    expect(campaignRequest(form({ frames: "" }))).toEqual({ error: "frames per set-point: empty: type a number" });
    expect(campaignRequest(form({ frames: "twenty" }))).toEqual({ error: 'frames per set-point: "twenty" is not a number' });
    const dynamic = campaignRequest(form({ kind: "profile", frames: "twenty" }));
    expect("body" in dynamic && !("frames_per_point" in dynamic.body)).toBe(true);
  });

  it("leaves the axes' limits to the server: an out-of-limit yaw is sent as typed (its 422 names the set-point)", () => {
    const r = campaignRequest(form({ fields: { yaw_deg: "0, 200" } }));
    expect("body" in r && r.body.generator).toMatchObject({ yaw_deg: [0, 200] });
  });

  it("builds a dynamic campaign's sine profile inside the generator", () => {
    const r = campaignRequest(form({ name: "sine", kind: "profile", fields: { amplitude_deg: "40", period_s: "0.5", rail_mm: "11000", rest_s: "0.5" } }));
    expect(r).toEqual({
      body: {
        name: "sine", record_raw: false,
        generator: {
          kind: "profile", rest_s: 0.5, yaw_deg: [0], pitch_deg: [0], roll_deg: [0], rail_mm: [11000],
          profile: { kind: "sine", axis: "yaw", amplitude_deg: 40, period_s: 0.5, cycles: 1 },
        },
      },
    });
  });

  it("leaves a ramp's optional acceleration out when empty, and sends it when typed", () => {
    const empty = generator("profile", "ramp", { axis: "pitch" });
    expect(empty).toEqual({
      generator: {
        kind: "profile", rest_s: 2, yaw_deg: [0], pitch_deg: [0], roll_deg: [0], rail_mm: [12000],
        profile: { kind: "ramp", axis: "pitch", rate_deg_s: 10, hold_s: 2 },
      },
    });
    expect(generator("profile", "ramp", { accel_deg_s2: "20" })).toMatchObject({ generator: { profile: { accel_deg_s2: 20 } } });
    expect(generator("profile", "ramp", { accel_deg_s2: "fast" })).toEqual({ error: 'accel deg/s² (optional): "fast" is not a number' });
  });

  it("sends text fields as typed (the server checks the axis name)", () => {
    expect(generator("attitude_steps", "sine", { axis: " pitch " })).toEqual({
      generator: { kind: "attitude_steps", axis: "pitch", steps_deg: [0, 1, 2, 5, 0], rail_mm: 12000 },
    });
  });
});

describe("form state", () => {
  it("offers every generator, and a profile's fields follow its shape", () => {
    expect(KINDS).toEqual(["grid", "range_sweep", "stability", "attitude_steps", "calibration", "profile"]);
    expect(params("profile", "sine").map((p) => p.key)).toEqual(
      ["axis", "amplitude_deg", "period_s", "cycles", "rest_s", "yaw_deg", "pitch_deg", "roll_deg", "rail_mm"]);
    expect(params("profile", "ramp").map((p) => p.key)).toEqual(
      ["axis", "rate_deg_s", "hold_s", "accel_deg_s2", "rest_s", "yaw_deg", "pitch_deg", "roll_deg", "rail_mm"]);
    expect(takesFrames("grid") && !takesFrames("profile")).toBe(true);
  });

  it("empties the fields when the generator changes", () => {
    const f = withKind(form({ name: "n", fields: { yaw_deg: "5" }, frames: "7" }), "stability");
    expect(f).toEqual(form({ name: "n", kind: "stability", fields: {}, frames: "7" }));
  });

  it("sets up a calibration campaign, named unless the user named it", () => {
    expect(calibrationPreset(form({ fields: { yaw_deg: "3" } }))).toEqual(form({ name: "bench-calibration", kind: "calibration" }));
    expect(calibrationPreset(form({ name: "mine" })).name).toBe("mine");
    expect(campaignRequest(calibrationPreset(INITIAL_FORM))).toMatchObject({
      body: { name: "bench-calibration", generator: { kind: "calibration", rails_mm: [11000, 12500] } },
    });
  });
});

describe("profileText", () => {
  it("says a set-point's profile in a few words", () => {
    expect(profileText({ kind: "sine", axis: "yaw", amplitude_deg: 2, period_s: 2, cycles: 1, rest_s: 0.5 }))
      .toBe("sine yaw 2 deg / 2 s x1, rests 0.5 s");
    expect(profileText({ kind: "ramp", axis: "roll", rate_deg_s: -5, hold_s: 3, rest_s: 2 })).toBe("ramp roll -5 deg/s for 3 s, rests 2 s");
    expect(profileText({ kind: "ramp", axis: "roll", rate_deg_s: 5, hold_s: 3, accel_deg_s2: 10, rest_s: 2 }))
      .toBe("ramp roll 5 deg/s for 3 s at 10 deg/s², rests 2 s");
  });
});
