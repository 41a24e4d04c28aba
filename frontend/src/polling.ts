// One way to poll the API: startPolling (no Preact: it is unit-tested with fake timers)
// and usePolling, the hook every polling panel uses.
import { useEffect, useRef, useState } from "preact/hooks";
import { errorText, useReportError } from "./errors";

export type PollResult<T> = { ok: true; data: T } | { ok: false; error: string };

export type Poller = {
  /** Ask now (besides the interval's requests). */
  refresh: () => void;
  /** Drop the answers of every request already sent (the state changed since they were). */
  invalidate: () => void;
  /** No more requests, and no answer is handed on any more. */
  stop: () => void;
};

/**
 * Calls `fetcher` now and then every `intervalMs` (null: once), handing each answer to
 * `onResult`, and calls `onTick` at each interval whether or not the last request has
 * answered (a clock for "no answer for 2 s"). Requests may overlap (a hung one does not
 * stop the polling); an answer is handed on only if no later request has answered already
 * and it was sent after the last `invalidate`, so an old state never replaces a newer one.
 */
export function startPolling<T>(
  fetcher: () => Promise<T>,
  intervalMs: number | null,
  onResult: (result: PollResult<T>) => void,
  onTick?: () => void,
): Poller {
  let sent = 0; // requests sent so far; a request's number is its order
  let answered = 0; // the newest request whose answer was handed on
  let floor = 1; // requests numbered below this were invalidated
  let stopped = false;
  const ask = () => {
    if (stopped) return;
    const n = ++sent;
    const hand = (result: PollResult<T>) => {
      if (stopped || n < floor || n <= answered) return;
      answered = n;
      onResult(result);
    };
    let pending: Promise<T>;
    try {
      pending = fetcher();
    } catch (e) {
      pending = Promise.reject(e);
    }
    pending.then((data) => hand({ ok: true, data }), (e) => hand({ ok: false, error: errorText(e) }));
  };
  ask();
  const timer = intervalMs === null ? undefined : setInterval(() => {
    onTick?.();
    ask();
  }, intervalMs);
  return {
    refresh: ask,
    invalidate: () => {
      floor = sent + 1;
    },
    stop: () => {
      stopped = true;
      if (timer !== undefined) clearInterval(timer);
    },
  };
}

export type Polled<T> = {
  data: T | null; // the newest answer (or value set), null until the first
  error: string | null; // the last request's error, null once one succeeds
  updatedAt: number; // Date.now() of the newest data, 0 before the first
  now: number; // Date.now() at the last interval (with `clock`), for staleness
  refresh: () => void;
  invalidate: () => void;
  /** A newer state from elsewhere (a command's answer): shown, and polls already sent dropped. */
  set: (data: T) => void;
};

/**
 * Polls `fetcher` every `intervalMs` (null: once) while the panel is shown, again when one
 * of `deps` changes; stops on unmount. A failed request's message goes to the page's error
 * banner (useReportError) and into `error`. `clock`: re-render at every interval (`now`).
 */
export function usePolling<T>(
  fetcher: () => Promise<T>,
  intervalMs: number | null,
  { deps = [], clock = false }: { deps?: unknown[]; clock?: boolean } = {},
): Polled<T> {
  const report = useReportError();
  const [state, setState] = useState<{ data: T | null; error: string | null; updatedAt: number }>(
    { data: null, error: null, updatedAt: 0 });
  const [now, setNow] = useState(() => Date.now());
  const poller = useRef<Poller | null>(null);
  const latest = useRef({ fetcher, report });
  latest.current = { fetcher, report };
  useEffect(() => {
    const p = startPolling(
      () => latest.current.fetcher(),
      intervalMs,
      (r) => {
        if (r.ok) setState({ data: r.data, error: null, updatedAt: Date.now() });
        else {
          setState((s) => ({ ...s, error: r.error }));
          latest.current.report(r.error);
        }
      },
      clock ? () => setNow(Date.now()) : undefined,
    );
    poller.current = p;
    return p.stop;
  }, [intervalMs, ...deps]);
  return {
    ...state,
    now,
    refresh: () => poller.current?.refresh(),
    invalidate: () => poller.current?.invalidate(),
    set: (data: T) => {
      poller.current?.invalidate();
      setState({ data, error: null, updatedAt: Date.now() });
    },
  };
}
