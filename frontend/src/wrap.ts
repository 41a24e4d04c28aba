// Distances beyond the camera's unambiguous range (issue 49): when a frame's distances
// had to be read whole unambiguous ranges further for the catalog to fit, the server
// says about which range (`distances_read_about_mm`); the live view says so, since the
// camera's own distance image then shows the target nearer than it is.
import type { Pose } from "./api/client";

/** The one-line notice under the images when the pose came from re-read distances, else null. */
export function wrapNotice(pose: Pick<Pose, "distances_read_about_mm"> | null | undefined): string | null {
  const about = pose?.distances_read_about_mm;
  if (about == null) return null;
  return (
    `distances read about ${(about / 1000).toFixed(1)} m: the target is beyond the range the ` +
    "camera's distances wrap at, so the distance image shows it nearer than it is"
  );
}
