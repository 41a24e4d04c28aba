// Strict parsing of what a person typed into a set-point field. `Number("")` is 0 and
// `Number(" 1e")` is NaN: neither may ever become a motion command, so a field is either
// a complete decimal number (optionally signed, with a fraction or an exponent) inside
// the axis' soft limits, or an error that says what is wrong.

const DECIMAL = /^[+-]?(\d+(\.\d+)?|\.\d+)([eE][+-]?\d+)?$/;

export type Limits = { name: string; unit: string; min_pos: number; max_pos: number };
export type Parsed = { value: number } | { error: string };

/** A number typed in full ("10", "-2.5", "1e3"), or why the text is not one. */
export function parseNumber(text: string): Parsed {
  const t = text.trim();
  if (t === "") return { error: "empty: type a number" };
  if (!DECIMAL.test(t)) return { error: `"${t}" is not a number` };
  const value = Number(t);
  if (!Number.isFinite(value)) return { error: `"${t}" is too large` };
  return { value };
}

/** A go-to set-point for one axis: a typed number inside its soft limits. */
export function parseSetpoint(text: string, axis: Limits): Parsed {
  const parsed = parseNumber(text);
  if ("error" in parsed) return parsed;
  if (parsed.value < axis.min_pos || parsed.value > axis.max_pos)
    return { error: `${parsed.value} ${axis.unit} is outside ${axis.name}'s limits ${axis.min_pos} .. ${axis.max_pos}` };
  return parsed;
}

/** A comma-separated list of numbers ("0, 5, 10"); every item must be a number. */
export function parseNumberList(text: string): { values: number[] } | { error: string } {
  const items = text.split(",").map((s) => s.trim());
  const values: number[] = [];
  for (const item of items) {
    const p = parseNumber(item);
    if ("error" in p) return { error: items.length > 1 ? `item "${item}": ${p.error}` : p.error };
    values.push(p.value);
  }
  return { values };
}
