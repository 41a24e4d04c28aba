// REST calls typed against the generated OpenAPI schema; errors become messages.
import type { components } from "./schema";

export type Pose = components["schemas"]["PosePublic"];
export type Motion = components["schemas"]["MotionPublic"];
export type Campaign = components["schemas"]["CampaignPublic"];
export type Study = components["schemas"]["StudyPublic"];
export type StudyCreate = components["schemas"]["StudyCreate"];
export type ApiError = components["schemas"]["ErrorPublic"];

const TOKEN_KEY = "tofpose-token";

export function token(): string | null {
  return sessionStorage.getItem(TOKEN_KEY);
}

export function setToken(value: string | null): void {
  if (value) sessionStorage.setItem(TOKEN_KEY, value);
  else sessionStorage.removeItem(TOKEN_KEY);
}

export class HttpError extends Error {
  constructor(public status: number, message: string) {
    super(message);
  }
}

function detailText(body: unknown): string {
  const d = (body as { detail?: unknown })?.detail;
  if (typeof d === "string") return d;
  if (Array.isArray(d)) return d.map((e) => `${(e.loc ?? []).join(".")}: ${e.msg}`).join("; ");
  return "unexpected answer";
}

export async function api<T>(method: string, path: string, body?: unknown): Promise<T> {
  const headers: Record<string, string> = {};
  const t = token();
  if (t) headers["Authorization"] = `Bearer ${t}`;
  if (body !== undefined) headers["Content-Type"] = "application/json";
  const r = await fetch(path, {
    method,
    headers,
    body: body === undefined ? undefined : JSON.stringify(body),
  });
  const parsed = r.headers.get("content-type")?.includes("json") ? await r.json() : null;
  if (!r.ok) {
    const hint = r.status === 401 ? " (enter the API token: data/api_token on the server)" : "";
    throw new HttpError(r.status, `${r.status}: ${detailText(parsed)}${hint}`);
  }
  return parsed as T;
}
