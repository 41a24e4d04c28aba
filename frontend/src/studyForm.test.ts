import { describe, expect, it } from "vitest";
import { expandRange, fieldErrors, INITIAL_FORM, specText, studyForm, studySpec, type StudyForm } from "./studyForm";

const form = (part: Partial<StudyForm>): StudyForm => ({ ...structuredClone(INITIAL_FORM), ...part });
const range = (start: string, stop: string, step: string) => ({ mode: "range" as const, list: "", start, stop, step });

describe("form -> spec", () => {
  it("sends a range as its values, lists as typed, and leaves empty fields to the server", () => {
    const f = form({
      axes: { ...INITIAL_FORM.axes, range_m: range("3", "8", "2.5"), attitude_deg: { ...INITIAL_FORM.axes.attitude_deg, list: "5, 20" } },
      physics: ["ideal"], requirements: { ...INITIAL_FORM.requirements, z_mm: "40", percentile: "99" },
    });
    const spec = studySpec(f);
    expect(spec).toEqual({
      body: {
        name: "envelope", seed: 1, frames_per_cell: 8, chunk_frames: 4,
        grid: { range_m: [3, 5.5, 8], attitude_deg: [5, 20], physics: ["ideal"] },
        requirements: { z_mm: 40, percentile: 99 },
      },
    });
  });

  it("rounds a decimal step's values and refuses a step that makes too many", () => {
    expect(expandRange(0.1, 0.5, 0.1)).toEqual({ values: [0.1, 0.2, 0.3, 0.4, 0.5] });
    expect(expandRange(3, 2, 1)).toEqual({ error: "stop 2 is below start 3" });
    expect(expandRange(0, 1, 0)).toEqual({ error: "step must be > 0" });
    expect(expandRange(0, 100, 1)).toEqual({ error: "101 values (at most 64): take a larger step" });
  });

  it("names every field that is not a number, by the server's path", () => {
    const f = form({
      frames_per_cell: "many",
      axes: { ...INITIAL_FORM.axes, range_m: range("3", "x", "1") },
      requirements: { ...INITIAL_FORM.requirements, pitch_deg: "0.1.5" },
    });
    expect(studySpec(f)).toEqual({
      errors: {
        frames_per_cell: '"many" is not a number',
        "grid.range_m": 'stop: "x" is not a number',
        "requirements.pitch_deg": '"0.1.5" is not a number',
      },
    });
  });
});

describe("spec -> form -> spec", () => {
  it("shows an evenly spaced list as a range and gives back the same spec", () => {
    const spec = {
      name: "s", seed: 3, frames_per_cell: 20, chunk_frames: 5,
      grid: { range_m: [2, 4, 6, 8], attitude_deg: [5, 20], ambient_lux: [1000], physics: ["ideal", "all"], preset: ["paper"], catalog: ["paper-target"] },
      requirements: { x_mm: 5, pitch_deg: 0.2 },
    };
    const parsed = studyForm(spec);
    if (!("form" in parsed)) throw new Error(parsed.error);
    expect(parsed.form.axes.range_m).toEqual({ mode: "range", list: "2, 4, 6, 8", start: "2", stop: "8", step: "2" });
    expect(parsed.form.axes.attitude_deg.mode).toBe("list");
    expect(parsed.form.requirements.pitch_deg).toBe("0.2");
    expect(studySpec(parsed.form)).toEqual({ body: spec });
    // and the JSON view of that form is the same spec
    expect(JSON.parse(specText(parsed.form))).toEqual(spec);
  });

  it("keeps an axis as it was typed while the JSON edit leaves its values alone", () => {
    const before = form({ axes: { ...INITIAL_FORM.axes, range_m: range("2.5", "5", "2.5") } });
    const spec = JSON.parse(specText(before));
    expect(spec.grid.range_m).toEqual([2.5, 5]);
    const kept = studyForm({ ...spec, seed: 7 }, before);
    if (!("form" in kept)) throw new Error(kept.error);
    expect(kept.form.axes.range_m).toEqual(range("2.5", "5", "2.5"));
    expect(kept.form.seed).toBe("7");
    // values changed in the JSON: the axis shows them
    const changed = studyForm({ ...spec, grid: { ...spec.grid, range_m: [2.5, 6] } }, before);
    if (!("form" in changed)) throw new Error(changed.error);
    expect(changed.form.axes.range_m).toEqual({ mode: "list", list: "2.5, 6", start: "", stop: "", step: "" });
  });

  it("keeps what the form has no field for, so that the server names it", () => {
    const parsed = studyForm({ name: "s", grid: { range_m: [3] }, colour: "red" });
    if (!("form" in parsed)) throw new Error(parsed.error);
    expect(studySpec(parsed.form)).toEqual({ body: { name: "s", colour: "red", grid: { range_m: [3] } } });
  });

  it("refuses a spec the form cannot show, naming the field", () => {
    expect(studyForm([1])).toEqual({ error: "the study spec must be a JSON object" });
    expect(studyForm({ grid: { range: [3] } })).toEqual({ error: "grid.range: not an axis of the form (range_m, attitude_deg, offset_fraction, ambient_lux, physics, preset, catalog)" });
    expect(studyForm({ grid: {}, requirements: { pitch: 1 } })).toMatchObject({ error: expect.stringContaining("requirements.pitch: not a requirement") });
  });
});

describe("a 422 by field", () => {
  it("puts each message at the field its location names", () => {
    const body = {
      detail: [
        { loc: ["body", "grid", "range_m", 1], msg: "a value is listed twice" },
        { loc: ["body", "requirements", "pitch_deg"], msg: "Input should be greater than 0" },
        { loc: ["body", "frames_per_cell"], msg: "too many" },
        { loc: ["body", "colour"], msg: "Extra inputs are not permitted" },
      ],
    };
    expect(fieldErrors(body)).toEqual({
      "grid.range_m": "a value is listed twice",
      "requirements.pitch_deg": "Input should be greater than 0",
      frames_per_cell: "too many",
      "": "colour: Extra inputs are not permitted",
    });
    expect(fieldErrors({ detail: "study limit" })).toEqual({ "": "study limit" });
  });
});
