// The new-study form's state and the spec it stands for (Studies.tsx draws it): the grid's
// number axes each as a list ("3, 5, 8") or a range (start, stop, step: 3, 8, 2.5 ->
// 3, 5.5, 8), the physics families and presets as choices, the catalogs as a list of
// names, frames per cell, seed, chunk size and the requirements. `studySpec` turns the
// form into POST /api/studies' body (or the fields it cannot read); `studyForm` turns a
// spec (the JSON view's text) back into the form, so either view can be edited and the
// other follows. An empty field is not sent: the server's default applies (its value is
// the field's placeholder). Limits (ranges, axis lengths, requirement bounds) are the
// server's to check: its 422 names the field, and `fieldErrors` puts its message there.
import type { StudyCreate } from "./api/client";
import { parseNumber, parseNumberList } from "./setpoint";

export const NUMBER_AXES = ["range_m", "attitude_deg", "offset_fraction", "ambient_lux"] as const;
export type NumberAxis = (typeof NUMBER_AXES)[number];
export const AXIS_LABEL: Record<NumberAxis, string> = {
  range_m: "range m",
  attitude_deg: "attitude spread ± deg",
  offset_fraction: "off-axis fraction",
  ambient_lux: "ambient lx",
};
// tofpose.sim.randomise.FAMILIES and tofpose.study.spec.PRESETS, as the schema lists them
// (a value the schema does not know fails tsc here)
export const PHYSICS: NonNullable<StudyCreate["grid"]["physics"]> = ["ideal", "grey plate", "lens blur", "gains", "systematic", "background", "all"];
export const PRESETS: NonNullable<StudyCreate["grid"]["preset"]> = ["default", "paper"];
export const REQUIREMENTS = ["x_mm", "y_mm", "z_mm", "pitch_deg", "yaw_deg", "roll_deg", "percentile"] as const;
export type RequirementKey = (typeof REQUIREMENTS)[number];
export const REQUIREMENT_LABEL: Record<RequirementKey, string> = {
  x_mm: "x mm", y_mm: "y mm", z_mm: "z mm", pitch_deg: "pitch deg", yaw_deg: "yaw deg", roll_deg: "roll deg",
  percentile: "% of frames within",
};
const TOP = ["name", "seed", "frames_per_cell", "chunk_frames"] as const;

/** One number axis as typed: a list, or start / stop / step. */
export type AxisForm = { mode: "list" | "range"; list: string; start: string; stop: string; step: string };

/** Everything the form holds, as typed. `extra`: what a JSON spec held that the form has no
 * field for, sent as it was (so the server names it). */
export type StudyForm = {
  name: string; seed: string; frames_per_cell: string; chunk_frames: string;
  axes: Record<NumberAxis, AxisForm>;
  physics: string[]; preset: string[]; catalog: string;
  requirements: Record<RequirementKey, string>;
  extra: Record<string, unknown>;
};

const listAxis = (list: string): AxisForm => ({ mode: "list", list, start: "", stop: "", step: "" });

export const INITIAL_FORM: StudyForm = {
  name: "envelope", seed: "1", frames_per_cell: "8", chunk_frames: "4",
  axes: { range_m: listAxis("3, 6"), attitude_deg: listAxis("20"), offset_fraction: listAxis(""), ambient_lux: listAxis("") },
  physics: ["ideal", "lens blur"], preset: [], catalog: "",
  requirements: { x_mm: "", y_mm: "", z_mm: "", pitch_deg: "", yaw_deg: "", roll_deg: "", percentile: "" },
  extra: {},
};

/** At most this many values on one axis (the server's StudyGrid takes 64). */
export const MAX_AXIS_VALUES = 64;

/** The values of start, start + step, ... up to stop (both ends included, within 1e-9 of a
 * step), rounded to 12 significant digits so that 0.1 steps read 0.3, not 0.30000000000000004. */
export function expandRange(start: number, stop: number, step: number): { values: number[] } | { error: string } {
  if (!(step > 0)) return { error: "step must be > 0" };
  if (stop < start) return { error: `stop ${stop} is below start ${start}` };
  const n = Math.floor((stop - start) / step + 1e-9) + 1;
  if (n > MAX_AXIS_VALUES) return { error: `${n} values (at most ${MAX_AXIS_VALUES}): take a larger step` };
  return { values: Array.from({ length: n }, (_, k) => Number((start + k * step).toPrecision(12))) };
}

/** An axis' values, or what is wrong; null: left empty (the server's default). */
export function axisValues(axis: AxisForm): { values: number[] | null } | { error: string } {
  if (axis.mode === "list") {
    if (axis.list.trim() === "") return { values: null };
    return parseNumberList(axis.list);
  }
  if ([axis.start, axis.stop, axis.step].every((t) => t.trim() === "")) return { values: null };
  const parts: number[] = [];
  for (const [label, text] of [["start", axis.start], ["stop", axis.stop], ["step", axis.step]] as const) {
    const p = parseNumber(text);
    if ("error" in p) return { error: `${label}: ${p.error}` };
    parts.push(p.value);
  }
  return expandRange(parts[0], parts[1], parts[2]);
}

/** A field's path as the server names it in a 422 ("grid.range_m", "requirements.z_mm"). */
export type FieldPath = string;

/** POST /api/studies' body from the form, or the fields that are not numbers (by path). */
export function studySpec(form: StudyForm): { body: StudyCreate } | { errors: Record<FieldPath, string> } {
  const errors: Record<FieldPath, string> = {};
  const body: Record<string, unknown> = { ...form.extra };
  const grid: Record<string, unknown> = {};
  const requirements: Record<string, number> = {};
  body.name = form.name;
  for (const key of ["seed", "frames_per_cell", "chunk_frames"] as const) {
    if (form[key].trim() === "") continue;
    const p = parseNumber(form[key]);
    if ("error" in p) errors[key] = p.error;
    else body[key] = p.value;
  }
  for (const axis of NUMBER_AXES) {
    const v = axisValues(form.axes[axis]);
    if ("error" in v) errors[`grid.${axis}`] = v.error;
    else if (v.values) grid[axis] = v.values;
  }
  if (form.physics.length) grid.physics = form.physics;
  if (form.preset.length) grid.preset = form.preset;
  const catalogs = form.catalog.split(",").map((s) => s.trim()).filter(Boolean);
  if (catalogs.length) grid.catalog = catalogs;
  body.grid = grid;
  for (const key of REQUIREMENTS) {
    const text = form.requirements[key];
    if (text.trim() === "") continue;
    const p = parseNumber(text);
    if ("error" in p) errors[`requirements.${key}`] = p.error;
    else requirements[key] = p.value;
  }
  if (Object.keys(requirements).length) body.requirements = requirements;
  if (Object.keys(errors).length) return { errors };
  // built key by key from the schema's own names (NUMBER_AXES, PHYSICS, REQUIREMENTS);
  // the values are numbers and lists as parsed above, the rest is the server's to check
  return { body: body as StudyCreate };
}

/** A list of numbers as the form shows it: evenly spaced (3 or more) as a range. */
function axisForm(values: unknown): AxisForm {
  if (!Array.isArray(values) || !values.every((v) => typeof v === "number")) return listAxis(values === undefined ? "" : JSON.stringify(values));
  const nums = values as number[];
  if (nums.length >= 3) {
    const step = nums[1] - nums[0];
    const even = step > 0 && nums.every((v, k) => Math.abs(v - (nums[0] + k * step)) <= 1e-9 * Math.max(1, Math.abs(v)));
    if (even) return { mode: "range", list: nums.join(", "), start: String(nums[0]), stop: String(nums[nums.length - 1]), step: String(Number(step.toPrecision(12))) };
  }
  return listAxis(nums.join(", "));
}

const text = (v: unknown): string => (v === undefined || v === null ? "" : typeof v === "string" ? v : JSON.stringify(v));
const strings = (v: unknown): string[] => (Array.isArray(v) ? v.map(String) : []);

/** Whether an axis as typed stands for these values. */
function same(axis: AxisForm, values: unknown): boolean {
  const v = axisValues(axis);
  if ("error" in v) return false;
  if (v.values === null) return values === undefined;
  return Array.isArray(values) && values.length === v.values.length && values.every((x, k) => x === v.values?.[k]);
}

/** The form that stands for a spec (the JSON view's parsed text), or why it cannot. What the
 * form has no field for is kept in `extra` and sent as it was. `previous`: the form as it
 * was; an axis whose values did not change keeps the way it was typed (a range stays a
 * range). */
export function studyForm(spec: unknown, previous?: StudyForm): { form: StudyForm } | { error: string } {
  if (typeof spec !== "object" || spec === null || Array.isArray(spec)) return { error: "the study spec must be a JSON object" };
  const doc = spec as Record<string, unknown>;
  const grid = (doc.grid ?? {}) as Record<string, unknown>;
  if (typeof grid !== "object" || grid === null || Array.isArray(grid)) return { error: "grid: must be an object of axes" };
  const req = (doc.requirements ?? {}) as Record<string, unknown>;
  if (typeof req !== "object" || req === null || Array.isArray(req)) return { error: "requirements: must be an object of axes" };
  const extra: Record<string, unknown> = {};
  for (const [k, v] of Object.entries(doc)) if (!(TOP as readonly string[]).includes(k) && k !== "grid" && k !== "requirements") extra[k] = v;
  const known = [...NUMBER_AXES, "physics", "preset", "catalog"];
  const unknownAxes = Object.keys(grid).filter((k) => !known.includes(k));
  const unknownReq = Object.keys(req).filter((k) => !(REQUIREMENTS as readonly string[]).includes(k));
  if (unknownAxes.length) return { error: `grid.${unknownAxes[0]}: not an axis of the form (${known.join(", ")})` };
  if (unknownReq.length) return { error: `requirements.${unknownReq[0]}: not a requirement (${REQUIREMENTS.join(", ")})` };
  const axes = Object.fromEntries(NUMBER_AXES.map((a) => [
    a, previous && same(previous.axes[a], grid[a]) ? previous.axes[a] : axisForm(grid[a]),
  ])) as Record<NumberAxis, AxisForm>;
  const requirements = Object.fromEntries(REQUIREMENTS.map((k) => [k, text(req[k])])) as Record<RequirementKey, string>;
  return {
    form: {
      name: text(doc.name), seed: text(doc.seed), frames_per_cell: text(doc.frames_per_cell), chunk_frames: text(doc.chunk_frames),
      axes, physics: strings(grid.physics), preset: strings(grid.preset), catalog: strings(grid.catalog).join(", "),
      requirements, extra,
    },
  };
}

/** The JSON view's text of a form: its spec, or (when a field is not a number) the spec of
 * every field that is, so the view never shows stale numbers. */
export function specText(form: StudyForm): string {
  const spec = studySpec(form);
  if ("body" in spec) return JSON.stringify(spec.body, null, 2);
  const cleared = structuredClone(form);
  for (const path of Object.keys(spec.errors)) {
    const [head, key] = path.split(".");
    if (head === "grid") cleared.axes[key as NumberAxis] = listAxis("");
    else if (head === "requirements") cleared.requirements[key as RequirementKey] = "";
    else cleared[head as "seed" | "frames_per_cell" | "chunk_frames"] = "";
  }
  const again = studySpec(cleared);
  return "body" in again ? JSON.stringify(again.body, null, 2) : "{}";
}

/** A 422's detail as messages by field path: the location after "body", cut to the field
 * the form has ("grid.range_m.1" -> "grid.range_m"); what names no field of the form goes
 * under "" (the form as a whole). */
export function fieldErrors(body: unknown): Record<FieldPath, string> {
  const detail = (body as { detail?: unknown } | null | undefined)?.detail;
  const out: Record<FieldPath, string> = {};
  const add = (path: string, msg: string) => { out[path] = out[path] ? `${out[path]}; ${msg}` : msg; };
  if (typeof detail === "string") { add("", detail); return out; }
  if (!Array.isArray(detail)) { add("", "unexpected answer"); return out; }
  for (const e of detail as { loc?: (string | number)[]; msg?: string }[]) {
    const loc = (e?.loc ?? []).filter((p, k) => !(k === 0 && p === "body")).map(String);
    const msg = e?.msg ?? "invalid";
    if ((loc[0] === "grid" || loc[0] === "requirements") && loc.length >= 2) add(`${loc[0]}.${loc[1]}`, msg);
    else if (loc.length >= 1 && (TOP as readonly string[]).includes(loc[0])) add(loc[0], msg);
    else add("", loc.length ? `${loc.join(".")}: ${msg}` : msg);
  }
  return out;
}
