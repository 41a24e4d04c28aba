import type { ComponentChildren } from "preact";
import type { Pose } from "../api/client";
import type { LiveLatency } from "../latency";
import { pixelFitText } from "../pixelFit";
import { LatencyReadout } from "./LatencyReadout";

const fmt = (v: number | null | undefined, d = 2) => (v === null || v === undefined ? "-" : v.toFixed(d));

export function PosePanel({ pose, stale, latency, children }: { pose: Pose | null; stale: boolean; latency?: LiveLatency | null; children?: ComponentChildren }) {
  if (!pose) return <section class="card"><h2>Pose</h2><p>no frame yet</p><LatencyReadout latency={latency ?? null} />{children}</section>;
  const ps = pose.position_sigma_mm ?? [];
  const as = pose.attitude_sigma_deg ?? [];
  const rows: [string, number | null | undefined, number | undefined, string, number][] = [
    ["x", pose.x_mm, ps[0], "mm", 2], ["y", pose.y_mm, ps[1], "mm", 2], ["z", pose.z_mm, ps[2], "mm", 2],
    ["pitch", pose.pitch_deg, as[0], "deg", 3], ["yaw", pose.yaw_deg, as[1], "deg", 3], ["roll", pose.roll_deg, as[2], "deg", 3],
  ];
  return (
    <section class={`card ${stale ? "stale" : ""}`}>
      <h2>Pose {stale && <span class="badge warn" data-testid="stale">stale: no frame for 2 s</span>}</h2>
      {pose.ok ? (
        <table class="pose" data-testid="pose">
          <tbody>
            {rows.map(([n, v, s, u, d]) => (
              <tr key={n}><th>{n}</th><td data-testid={`pose-${n}`}>{fmt(v, d)}</td><td>± {fmt(s, d)}</td><td>{u}</td></tr>
            ))}
          </tbody>
        </table>
      ) : (
        <p class="error" data-testid="no-pose">no pose: {pose.reason}</p>
      )}
      <p class="small">frame {pose.frame_index}, {pose.n_matched} matched of {pose.n_candidates} candidates,
        residual {fmt(pose.residual_mm, 3)} mm, {fmt(pose.timings_ms["total"], 1)} ms
        (<span data-testid="pose-mode">{pose.mode}</span>);
        attitude relative to the facing reference (face-on reads 0, 0, 0)</p>
      {pose.ok && pixelFitText(pose) && <p class="small" data-testid="pose-pixel-fit">{pixelFitText(pose)}</p>}
      <LatencyReadout latency={latency ?? null} />
      {pose.angular_rate_deg_s && (
        <table class="pose" data-testid="rates">
          <thead><tr><th></th><th>rate (deg/s)</th><th>velocity (mm/s)</th></tr></thead>
          <tbody>
            {["x", "y", "z"].map((n, i) => (
              <tr key={n}>
                <th>{n}</th>
                <td><span data-testid={`rate-${n}`}>{fmt(pose.angular_rate_deg_s?.[i], 2)}</span> ± {fmt(pose.angular_rate_sigma_deg_s?.[i], 2)}</td>
                <td>{fmt(pose.velocity_mm_s?.[i], 1)} ± {fmt(pose.velocity_sigma_mm_s?.[i], 1)}</td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
      {pose.filter_status && (
        <p class="small">relative state (camera frame): <span data-testid="filter-status">{pose.filter_status}</span>
          {pose.filter_status === "rejected" && " (this pose disagrees with the motion so far and was not fused)"}</p>
      )}
      {pose.reference && (
        <p class="small" data-testid="pose-reference">lab reference, {pose.reference.label}: x {fmt(pose.reference.x_mm)} y {fmt(pose.reference.y_mm)} z {fmt(pose.reference.z_mm)} mm;
          error vs reference <span data-testid="pose-reference-error-mm">{fmt(pose.reference.position_error_mm)}</span> mm, {fmt(pose.reference.attitude_error_deg, 3)} deg</p>
      )}
      {children}
    </section>
  );
}
