import { afterEach, describe, expect, it, vi } from "vitest";
import { connectLive, liveProtocols } from "./live";

/** A WebSocket stand-in that records how it was opened. */
class FakeSocket {
  static opened: { url: string; protocols: string[] }[] = [];
  static OPEN = 1;
  readyState = 0;
  binaryType = "blob";
  onopen: (() => void) | null = null;
  onmessage: ((ev: { data: unknown }) => void) | null = null;
  onclose: (() => void) | null = null;
  constructor(url: string, protocols: string[] = []) {
    FakeSocket.opened.push({ url, protocols });
  }
  send() {}
  close() {}
}

function stubPage(stored: string | null) {
  FakeSocket.opened = [];
  vi.stubGlobal("WebSocket", FakeSocket);
  vi.stubGlobal("location", { protocol: "http:", host: "lab.test:8000" });
  vi.stubGlobal("sessionStorage", { getItem: () => stored });
  vi.stubGlobal("window", { setInterval: () => 0, clearInterval: () => {}, setTimeout: () => 0, clearTimeout: () => {} });
  vi.stubGlobal("requestAnimationFrame", () => 0);
}

describe("the live socket's key", () => {
  afterEach(() => vi.unstubAllGlobals());

  it("is offered as the subprotocol tofpose.bearer.<key> beside tofpose.bearer, or not at all", () => {
    expect(liveProtocols(null)).toEqual([]);
    expect(liveProtocols("")).toEqual([]);
    expect(liveProtocols("abc_-9")).toEqual(["tofpose.bearer", "tofpose.bearer.abc_-9"]);
  });

  it("goes in the handshake, never in the URL", () => {
    stubPage("s3cret-key");
    connectLive(() => {}).close();
    expect(FakeSocket.opened).toEqual([
      { url: "ws://lab.test:8000/ws/live", protocols: ["tofpose.bearer", "tofpose.bearer.s3cret-key"] },
    ]);
  });

  it("is left out when the page has none (reads open on loopback)", () => {
    stubPage(null);
    connectLive(() => {}).close();
    expect(FakeSocket.opened).toEqual([{ url: "ws://lab.test:8000/ws/live", protocols: [] }]);
  });
});
