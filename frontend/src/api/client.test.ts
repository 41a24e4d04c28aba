import { describe, expect, it } from "vitest";
import { createApi, detailText, errorMessage, HttpError, serverDefaults, unwrap, type RequestBody } from "./client";

type Seen = { method: string; url: string; auth: string | null; type: string | null; body: string };

/** A client whose requests go to `answer` instead of the network, and what it was sent. */
function fake(status: number, body: unknown, token: string | null = null, contentType = "application/json") {
  const seen: Seen[] = [];
  const fetch = async (input: RequestInfo | URL): Promise<Response> => {
    const r = input as Request;
    seen.push({ method: r.method, url: r.url, auth: r.headers.get("Authorization"), type: r.headers.get("Content-Type"), body: await r.text() });
    const text = typeof body === "string" ? body : JSON.stringify(body);
    return new Response(status === 204 ? null : text, { status, headers: { "Content-Type": contentType } });
  };
  return { api: createApi({ baseUrl: "http://lab.test", fetch, token: () => token }), seen };
}

describe("the typed client", () => {
  it("sends the stored token as a Bearer header, and a JSON body with its content type", async () => {
    const { api, seen } = fake(202, { busy: true }, "s3cret");
    const data = await unwrap(api.POST("/api/motion/move", { body: { pitch_deg: 2.5 } }));
    expect(data).toEqual({ busy: true });
    expect(seen).toEqual([{
      method: "POST", url: "http://lab.test/api/motion/move", auth: "Bearer s3cret", type: "application/json", body: '{"pitch_deg":2.5}',
    }]);
  });

  it("sends no Authorization header without a token, and no content type without a body", async () => {
    const { api, seen } = fake(200, { stopped: true });
    await unwrap(api.POST("/api/motion/stop"));
    expect(seen[0].auth).toBeNull();
    expect(seen[0].type).toBeNull();
    expect(seen[0].body).toBe("");
  });

  it("puts path parameters into the path", async () => {
    const { api, seen } = fake(200, {});
    await unwrap(api.GET("/api/campaigns/{campaign_id}/report.{fmt}", { params: { path: { campaign_id: 12, fmt: "json" } } }));
    expect(seen[0].url).toBe("http://lab.test/api/campaigns/12/report.json");
  });

  it("turns a 401 into its status, the server's reason and where the token is", async () => {
    const { api } = fake(401, { detail: "missing or wrong API token" });
    const err = await unwrap(api.POST("/api/motion/move", { body: { roll_deg: 90 } })).catch((e) => e);
    expect(err).toBeInstanceOf(HttpError);
    expect(err.status).toBe(401);
    expect(err.message).toBe("401: missing or wrong API token (enter the API token: data/api_token on the server)");
  });

  it("lists a 422's validation errors as 'loc: msg; ...'", async () => {
    const { api } = fake(422, {
      detail: [
        { loc: ["body", "generator", "yaw_deg", 1], msg: "yaw set-point 200 outside -170 .. 170", type: "value_error" },
        { loc: ["body", "name"], msg: "Field required", type: "missing" },
      ],
    });
    const err = await unwrap(api.POST("/api/campaigns", {
      body: serverDefaults<RequestBody<"/api/campaigns", "post">, "catalog" | "frames_per_point" | "lock_timeout_s" | "notes" | "settle_s">({
        name: "", generator: { kind: "grid", yaw_deg: [0, 200] }, record_raw: false }),
    })).catch((e) => e);
    expect(err.message).toBe("422: body.generator.yaw_deg.1: yaw set-point 200 outside -170 .. 170; body.name: Field required");
  });

  it("says 'unexpected answer' for an error body that is not JSON", async () => {
    const { api } = fake(502, "<html>bad gateway</html>", null, "text/html");
    await expect(unwrap(api.GET("/api/motion"))).rejects.toThrow("502: unexpected answer");
  });
});

describe("error text", () => {
  it("formats FastAPI's detail: a string, a list, or anything else", () => {
    expect(detailText({ detail: "campaign 3 not found" })).toBe("campaign 3 not found");
    expect(detailText({ detail: [{ loc: ["query", "limit"], msg: "too big" }, { msg: "no place" }] })).toBe("query.limit: too big; : no place");
    expect(detailText(null)).toBe("unexpected answer");
    expect(detailText("plain text")).toBe("unexpected answer");
    expect(errorMessage(409, { detail: "busy" })).toBe("409: busy");
  });
});
