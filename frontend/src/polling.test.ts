import { afterEach, beforeEach, describe, expect, it, vi } from "vitest";
import { startPolling, type PollResult } from "./polling";

/** A fetcher whose answers the test releases one by one, in any order. */
function controlled<T>() {
  const calls: { resolve: (v: T) => void; reject: (e: Error) => void }[] = [];
  const fetcher = () => new Promise<T>((resolve, reject) => calls.push({ resolve, reject }));
  return { fetcher, calls };
}
const flush = () => vi.advanceTimersByTimeAsync(0);

describe("startPolling", () => {
  beforeEach(() => vi.useFakeTimers());
  afterEach(() => vi.useRealTimers());

  it("asks at once and then every interval, ticking even while requests are unanswered", async () => {
    const { fetcher, calls } = controlled<number>();
    const ticks = vi.fn();
    const p = startPolling(fetcher, 500, () => {}, ticks);
    expect(calls.length).toBe(1);
    await vi.advanceTimersByTimeAsync(1499);
    expect(calls.length).toBe(3); // at 0, 500, 1000 ms; none answered (a hung link)
    expect(ticks).toHaveBeenCalledTimes(2);
    p.stop();
  });

  it("hands on answers and errors, and stops asking and handing on after stop", async () => {
    const { fetcher, calls } = controlled<number>();
    const results: PollResult<number>[] = [];
    const p = startPolling(fetcher, 1000, (r) => results.push(r));
    calls[0].resolve(1);
    await flush();
    await vi.advanceTimersByTimeAsync(1000);
    calls[1].reject(new Error("Failed to fetch"));
    await flush();
    expect(results).toEqual([{ ok: true, data: 1 }, { ok: false, error: "Failed to fetch" }]);
    await vi.advanceTimersByTimeAsync(1000);
    p.stop();
    calls[2].resolve(3); // answered after the panel went away
    await vi.advanceTimersByTimeAsync(5000);
    expect(calls.length).toBe(3);
    expect(results.length).toBe(2);
  });

  it("never replaces a newer answer with an older one", async () => {
    const { fetcher, calls } = controlled<string>();
    const seen: string[] = [];
    const p = startPolling(fetcher, 100, (r) => r.ok && seen.push(r.data));
    await vi.advanceTimersByTimeAsync(100);
    calls[1].resolve("new");
    await flush();
    calls[0].resolve("old"); // slower, sent first
    await flush();
    expect(seen).toEqual(["new"]);
    p.stop();
  });

  it("drops the answers of requests sent before invalidate (a change made since)", async () => {
    const { fetcher, calls } = controlled<string>();
    const seen: string[] = [];
    const p = startPolling(fetcher, 100, (r) => r.ok && seen.push(r.data));
    p.invalidate();
    calls[0].resolve("before the change");
    await flush();
    p.refresh();
    calls[1].resolve("after the change");
    await flush();
    expect(seen).toEqual(["after the change"]);
    p.stop();
  });

  it("asks once with no interval, and turns a fetcher that throws into an error", async () => {
    const results: PollResult<number>[] = [];
    startPolling<number>(() => { throw new Error("no"); }, null, (r) => results.push(r));
    await vi.advanceTimersByTimeAsync(10_000);
    expect(results).toEqual([{ ok: false, error: "no" }]);
  });
});
