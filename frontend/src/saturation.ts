// Saturated reflectors (issue 49): the server marks each matched reflector whose pixels
// reach the camera's full scale (`saturated`) and counts them (`saturated_reflectors`);
// the live view labels them and says what to do. Nothing is recomputed here.
import type { Pose } from "./api/client";

type Matched = Pose["matched"][number];

/** The overlay's label of a matched reflector: its catalog id, and "saturated" when it is. */
export function reflectorLabel(m: Pick<Matched, "catalog_id" | "saturated">): string {
  return m.saturated ? `${m.catalog_id} saturated` : String(m.catalog_id);
}

/** The one-line warning under the images when matched reflectors saturate, else null. */
export function saturationWarning(pose: Pick<Pose, "saturated_reflectors"> | null | undefined): string | null {
  const n = pose?.saturated_reflectors ?? 0;
  if (n <= 0) return null;
  const what = n === 1 ? "1 reflector saturates" : `${n} reflectors saturate`;
  return `${what}: lower the integration time or turn auto exposure on`;
}
