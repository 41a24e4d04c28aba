// Small formatters shared by the dashboard's panels.

/** A duration in seconds as "3 min 20 s" or "45 s"; "-" when unknown. */
export function fmtDuration(s: number | null | undefined): string {
  if (s === null || s === undefined) return "-";
  const m = Math.floor(s / 60);
  return m > 0 ? `${m} min ${Math.round(s % 60)} s` : `${s.toFixed(0)} s`;
}

/** A Unix time as the local wall clock, 24 h: "14:05:03", or "14:05:03.25" with `digits`
 * digits of the second. */
export function fmtClock(unixS: number, digits = 0): string {
  const d = new Date(unixS * 1000);
  const two = (n: number) => String(n).padStart(2, "0");
  const hms = `${two(d.getHours())}:${two(d.getMinutes())}:${two(d.getSeconds())}`;
  if (digits <= 0) return hms;
  return `${hms}.${String(d.getMilliseconds()).padStart(3, "0").slice(0, Math.min(digits, 3))}`;
}
