// The pixel-level fit in the live loop (the server's TOFPOSE_PIXEL_FIT): each ok pose is
// refined on its markers' raw pixels, and the pose message says how that went
// (`pixel_fit`: "ok", or why the centroid pose stands). The pose panel says which pose
// and which sigmas it shows.
import type { Pose } from "./api/client";

/** The pose panel's line on the pixel fit, or null when the fit did not run. */
export function pixelFitText(pose: Pick<Pose, "pixel_fit" | "timings_ms"> | null | undefined): string | null {
  const fit = pose?.pixel_fit;
  if (!fit) return null;
  const ms = pose?.timings_ms?.["pixel fit"];
  const took = ms === undefined ? "" : ` (${ms.toFixed(0)} ms)`;
  if (fit === "ok") return `refined on the markers' pixels${took}: the pose and sigmas of the sensor model's fit`;
  return `pixel fit fell back${took}: the centroid pose and its sigmas (${fit})`;
}
