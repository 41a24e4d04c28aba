// The new-campaign form's state and what it sends (NewCampaign.tsx draws it): a generator
// of set-points, its fields as typed, the frames per set-point and whether to keep the raw
// frames. Every number field must be a number (or list of numbers) in full, or nothing is
// sent and the form says which field is wrong; the axes' limits are the server's to check
// (its 422 names the set-point).
import { serverDefaults, type RequestBody, type Schemas } from "./api/client";
import { parseNumber, parseNumberList } from "./setpoint";

/** Each generator kind and the request body part it becomes (schema.d.ts). */
type GeneratorOf = {
  grid: Schemas["GridGenerator"];
  range_sweep: Schemas["RangeSweepGenerator"];
  stability: Schemas["StabilityGenerator"];
  attitude_steps: Schemas["AttitudeStepsGenerator"];
  calibration: Schemas["CalibrationGenerator"];
  profile: Schemas["ProfileGenerator"];
};
type ProfileOf = { sine: Schemas["SineProfileRequest"]; ramp: Schemas["RampProfileRequest"] };
export type Kind = keyof GeneratorOf;
export type Shape = keyof ProfileOf;
export type Generator = GeneratorOf[Kind];
export type CampaignBody = RequestBody<"/api/campaigns", "post">;

type Field<T> = Exclude<keyof T, "kind" | "profile"> & string;

// Each parameter: its label and the default used when the field is left empty (shown as
// the field's placeholder, so what is sent is what the page shows). `optional`: left empty,
// the field is not sent (the server's default, which the placeholder names); `choices`: a
// select; `profile`: a field of the generator's motion profile (body.generator.profile).
// `key` is a field of that generator's (or profile's) schema: a renamed field fails tsc.
export type Param<K extends string = string> = { key: K; label: string; fallback: string; list?: boolean; text?: boolean;
  optional?: boolean; choices?: string[]; profile?: boolean };

// A dynamic campaign: the profile (its axis, sine or ramp and that shape's fields), the
// rests around it and the start points, every combination of the lists (as a grid).
const SHAPE_PARAMS: { [S in Shape]: Param<Field<ProfileOf[S]>>[] } = {
  sine: [
    { key: "amplitude_deg", label: "amplitude deg", fallback: "5", profile: true },
    { key: "period_s", label: "period s", fallback: "4", profile: true },
    { key: "cycles", label: "cycles", fallback: "1", profile: true },
  ],
  ramp: [
    { key: "rate_deg_s", label: "rate deg/s", fallback: "10", profile: true },
    { key: "hold_s", label: "hold s", fallback: "2", profile: true },
    { key: "accel_deg_s2", label: "accel deg/s² (optional)", fallback: "axis limit", optional: true, profile: true },
  ],
};

export const PARAMS: { [K in Kind]: Param<Field<GeneratorOf[K]> | (K extends "profile" ? Field<ProfileOf[Shape]> : never)>[] } = {
  grid: [
    { key: "yaw_deg", label: "yaw deg (list)", fallback: "0", list: true },
    { key: "pitch_deg", label: "pitch deg (list)", fallback: "0", list: true },
    { key: "roll_deg", label: "roll deg (list)", fallback: "0", list: true },
    { key: "rail_mm", label: "rail mm (list)", fallback: "12000", list: true },
  ],
  range_sweep: [
    { key: "rail_start_mm", label: "rail from mm", fallback: "9000" },
    { key: "rail_stop_mm", label: "rail to mm", fallback: "14000" },
    { key: "points", label: "points", fallback: "6" },
  ],
  stability: [{ key: "rail_mm", label: "rail mm", fallback: "14303" }],
  attitude_steps: [
    { key: "axis", label: "axis (yaw, pitch, roll)", fallback: "roll", text: true },
    { key: "steps_deg", label: "steps deg (list)", fallback: "0, 1, 2, 5, 0", list: true },
    { key: "rail_mm", label: "rail mm", fallback: "12000" },
  ],
  calibration: [{ key: "rails_mm", label: "rails mm (list)", fallback: "11000, 12500", list: true }],
  profile: [
    { key: "axis", label: "profile axis", fallback: "yaw", choices: ["yaw", "pitch", "roll"], profile: true },
    { key: "rest_s", label: "rest s (before, after)", fallback: "2" },
    { key: "yaw_deg", label: "start yaw deg (list)", fallback: "0", list: true },
    { key: "pitch_deg", label: "start pitch deg (list)", fallback: "0", list: true },
    { key: "roll_deg", label: "start roll deg (list)", fallback: "0", list: true },
    { key: "rail_mm", label: "rail mm (list)", fallback: "12000", list: true },
  ],
};

export const KINDS = Object.keys(PARAMS) as Kind[];
export const KIND_LABEL: Partial<Record<Kind, string>> = { profile: "dynamic (motion profile)" };

/** The fields of a generator kind (and, for a dynamic campaign, of its profile's shape). */
export function params(kind: Kind, shape: Shape): Param[] {
  if (kind !== "profile") return PARAMS[kind];
  const [axis, ...rest] = PARAMS.profile;
  return [axis, ...SHAPE_PARAMS[shape], ...rest];
}

/** The generator part of the body, or the first field that is not what it says. */
export function generator(kind: Kind, shape: Shape, fields: Record<string, string>): { generator: Generator } | { error: string } {
  const out: Record<string, unknown> = { kind };
  const profile: Record<string, unknown> = { kind: shape };
  if (kind === "profile") out.profile = profile;
  for (const param of params(kind, shape)) {
    const target = param.profile ? profile : out;
    const typed = (fields[param.key] ?? "").trim();
    if (param.optional && typed === "") continue;
    const raw = typed || param.fallback;
    if (param.text || param.choices) {
      target[param.key] = raw;
      continue;
    }
    const parsed = param.list ? parseNumberList(raw) : parseNumber(raw);
    if ("error" in parsed) return { error: `${param.label}: ${parsed.error}` };
    target[param.key] = "values" in parsed ? parsed.values : parsed.value;
  }
  // Built field by field from PARAMS, whose keys tsc checks against this kind's schema;
  // the values are numbers or lists as parsed above, text fields the server validates.
  return { generator: out as Generator };
}

/** The campaign's metadata, as typed (empty: not sent; the camera's serial and firmware are
 * read from the device where its driver reports them, docs/campaigns.md). */
export type Metadata = { operator: string; target_name: string; camera_serial: string; camera_firmware: string; notes: string };
export const METADATA_FIELDS: { key: keyof Metadata; label: string; title: string }[] = [
  { key: "operator", label: "operator", title: "who runs the campaign" },
  { key: "target_name", label: "target", title: "the target measured" },
  { key: "camera_serial", label: "camera serial", title: "empty: read from the camera where its driver reports it" },
  { key: "camera_firmware", label: "camera firmware", title: "empty: read from the camera where its driver reports it" },
  { key: "notes", label: "notes", title: "free text, printed in the report" },
];

/** Everything the form holds, as typed. */
export type CampaignForm = {
  name: string;
  kind: Kind;
  shape: Shape;
  fields: Record<string, string>; // by parameter key; empty or missing: the placeholder
  frames: string;
  recordRaw: boolean;
  integrationTimes: string; // a list: every set-point measured at each; empty: the camera's own
  modulations: string; // a list of MHz; empty: the camera's own
  metadata: Metadata;
};

export const INITIAL_FORM: CampaignForm = {
  name: "", kind: "grid", shape: "sine", fields: {}, frames: "20", recordRaw: false, integrationTimes: "", modulations: "",
  metadata: { operator: "", target_name: "", camera_serial: "", camera_firmware: "", notes: "" },
};

/** Another generator: its fields start empty. */
export function withKind(form: CampaignForm, kind: Kind): CampaignForm {
  return { ...form, kind, fields: {} };
}

/** The form set up for a calibration campaign (the reference bar's button). */
export function calibrationPreset(form: CampaignForm): CampaignForm {
  return { ...withKind(form, "calibration"), name: form.name || "bench-calibration" };
}

/** Whether a kind takes a frame count: a dynamic campaign keeps every frame of its rests and
 * profile. */
export function takesFrames(kind: Kind): boolean {
  return kind !== "profile";
}

/** The fields the form leaves to the server's defaults (catalog, settle time, ...). */
type ServerDefaulted = "catalog" | "frames_per_point" | "lock_timeout_s" | "notes" | "settle_s" | "camera_sweep"
  | "operator" | "target_name" | "camera_model" | "camera_serial" | "camera_firmware";

/** The camera sweep part of the body ({} when neither list is typed), or the list that is not
 * one. The camera's limits are the server's to check (its 422 names the field and the range). */
export function cameraSweep(form: CampaignForm): { camera_sweep?: Schemas["CameraSweep"] } | { error: string } {
  const sweep: Schemas["CameraSweep"] = {};
  for (const [key, label, typed] of [
    ["integration_time_us", "integration times us (list)", form.integrationTimes],
    ["modulation_frequency_mhz", "modulation MHz (list)", form.modulations],
  ] as const) {
    if (typed.trim() === "") continue;
    const parsed = parseNumberList(typed);
    if ("error" in parsed) return { error: `${label}: ${parsed.error}` };
    sweep[key] = parsed.values;
  }
  return Object.keys(sweep).length ? { camera_sweep: sweep } : {};
}

/** The metadata fields typed (trimmed; the empty ones are left out). */
export function metadataBody(metadata: Metadata): Partial<Metadata> {
  return Object.fromEntries(
    Object.entries(metadata).map(([k, v]) => [k, v.trim()]).filter(([, v]) => v !== ""),
  ) as Partial<Metadata>;
}

/** The POST /api/campaigns body, or what is wrong with the form (then nothing is sent). */
export function campaignRequest(form: CampaignForm): { body: CampaignBody } | { error: string } {
  const gen = generator(form.kind, form.shape, form.fields);
  if ("error" in gen) return gen;
  const frames = takesFrames(form.kind) ? parseNumber(form.frames) : null;
  if (frames && "error" in frames) return { error: `frames per set-point: ${frames.error}` };
  const sweep = cameraSweep(form);
  if ("error" in sweep) return sweep;
  return {
    body: serverDefaults<CampaignBody, ServerDefaulted>({
      name: form.name, ...(frames ? { frames_per_point: frames.value } : {}), generator: gen.generator, record_raw: form.recordRaw,
      ...sweep, ...metadataBody(form.metadata),
    }),
  };
}

/** A set-point's camera settings in a few words ("200 us, 12 MHz"); "-" for none. */
export function cameraText(camera: Record<string, number> | null | undefined): string {
  if (!camera) return "-";
  const parts = [];
  if (camera.integration_time_us != null) parts.push(`${camera.integration_time_us} us`);
  if (camera.modulation_frequency_mhz != null) parts.push(`${camera.modulation_frequency_mhz} MHz`);
  return parts.join(", ") || "-";
}

/** A set-point's motion profile in a few words ("sine yaw 2 deg / 2 s x1, rests 0.5 s"). */
export function profileText(pr: Record<string, unknown>): string {
  const shape = pr.kind === "sine"
    ? `${pr.amplitude_deg} deg / ${pr.period_s} s x${pr.cycles}`
    : `${pr.rate_deg_s} deg/s for ${pr.hold_s} s${pr.accel_deg_s2 != null ? ` at ${pr.accel_deg_s2} deg/s²` : ""}`;
  return `${pr.kind} ${pr.axis} ${shape}, rests ${pr.rest_s} s`;
}
