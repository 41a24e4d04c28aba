// The REST client, typed by the generated OpenAPI schema (openapi-fetch): a path, its
// parameters and its request body are checked by tsc against schema.d.ts, and the answer
// has the type the schema gives it (no type asserted by the caller). `unwrap` turns an
// answer into its data or throws an HttpError whose message the page shows.
import createClient, { type Client, type Middleware, type RequestBodyOption } from "openapi-fetch";
import type { components, paths } from "./schema";

export type Schemas = components["schemas"];
export type Pose = Schemas["PosePublic"];
export type Motion = Schemas["MotionPublic"];
export type Campaign = Schemas["CampaignPublic"];
export type Study = Schemas["StudyPublic"];
export type StudyCreate = Schemas["StudyCreate"];
export type ApiError = Schemas["ErrorPublic"];

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

export const TOKEN_HINT = " (enter the API token: data/api_token on the server)";

/** An error body as text: FastAPI's `detail`, a string or a list of validation errors
 * ("generator.yaw_deg: msg; ..."). */
export function detailText(body: unknown): string {
  const d = (body as { detail?: unknown } | null | undefined)?.detail;
  if (typeof d === "string") return d;
  if (Array.isArray(d))
    return d.map((e: { loc?: (string | number)[]; msg?: string }) => `${(e?.loc ?? []).join(".")}: ${e?.msg}`).join("; ");
  return "unexpected answer";
}

/** What the page says of a refused request: "422: loc: msg", with a hint at a 401. */
export function errorMessage(status: number, body: unknown): string {
  return `${status}: ${detailText(body)}${status === 401 ? TOKEN_HINT : ""}`;
}

/** The stored token as a Bearer header on every request. */
export function bearer(getToken: () => string | null): Middleware {
  return {
    onRequest({ request }) {
      const t = getToken();
      if (t) request.headers.set("Authorization", `Bearer ${t}`);
      return request;
    },
  };
}

export type ApiClient = Client<paths>;

/** A client of this server's API (the page's is `api`; tests pass their own fetch). */
export function createApi(options: { baseUrl?: string; fetch?: typeof fetch; token?: () => string | null } = {}): ApiClient {
  const client = createClient<paths>({ baseUrl: options.baseUrl ?? "", fetch: options.fetch });
  client.use(bearer(options.token ?? token));
  return client;
}

/** The page's client: same origin, the token from sessionStorage. */
export const api: ApiClient = createApi();

type Answer = { data?: unknown; error?: unknown; response: Response };
/** The data of a successful answer (typed by the schema for that path and method). */
export type DataOf<A> = A extends { data: infer D; error?: never } ? D : never;

/** The data of an answer, or an HttpError with the server's reason ("404: no campaign 3"). */
export async function unwrap<A extends Answer>(pending: Promise<A>): Promise<DataOf<A>> {
  const answer = await pending;
  if (!answer.response.ok) throw new HttpError(answer.response.status, errorMessage(answer.response.status, answer.error));
  return answer.data as DataOf<A>;
}

/** The JSON body of a path's method, as the client takes it. */
export type RequestBody<P extends keyof paths, M extends keyof paths[P]> = NonNullable<RequestBodyOption<paths[P][M]>["body"]>;

/** A request body that leaves out the fields named in K, which the server fills in with
 * their defaults. openapi-typescript marks every field that has a default as required (right
 * for answers, where the server always sends it); a request may leave it out. Every other
 * field is checked as usual. */
export type Defaulted<T, K extends keyof T> = T extends unknown ? Omit<T, K> & Partial<Pick<T, K>> : never;
export function serverDefaults<T, K extends keyof T>(body: Defaulted<T, K>): T {
  return body as T;
}
