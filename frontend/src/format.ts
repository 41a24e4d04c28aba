// Small formatters shared by the dashboard's panels.

/** A duration in seconds as "3 min 20 s" or "45 s"; "-" when unknown. */
export function fmtDuration(s: number | null | undefined): string {
  if (s === null || s === undefined) return "-";
  const m = Math.floor(s / 60);
  return m > 0 ? `${m} min ${Math.round(s % 60)} s` : `${s.toFixed(0)} s`;
}
