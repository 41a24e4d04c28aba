// Axis positions, go-to within the soft limits, and an always-visible STOP.
import { useEffect, useState } from "preact/hooks";
import { api, type Motion } from "../api/client";

const FIELDS: Record<string, string> = { yaw: "yaw_deg", pitch: "pitch_deg", roll: "roll_deg", rail: "rail_mm" };

export function MotionPanel({ onError }: { onError: (m: string | null) => void }) {
  const [motion, setMotion] = useState<Motion | null>(null);
  const [targets, setTargets] = useState<Record<string, string>>({});
  useEffect(() => {
    const poll = () => api<Motion>("GET", "/api/motion").then(setMotion).catch((e) => onError(String(e.message)));
    poll();
    const t = window.setInterval(poll, 500);
    return () => window.clearInterval(t);
  }, []);
  const go = async (body: Record<string, number>) => {
    try {
      setMotion(await api<Motion>("POST", "/api/motion/move", body));
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    }
  };
  if (!motion) return <section class="card"><h2>Turntable</h2><p>loading</p></section>;
  return (
    <section class="card">
      <h2>Turntable <span class="small">{motion.busy ? "moving" : motion.settled ? "settled" : "settling"}</span></h2>
      <table class="axes">
        <thead><tr><th>axis</th><th>position</th><th>limits</th><th>go to</th><th>jog</th></tr></thead>
        <tbody>
          {motion.axes.map((a) => (
            <tr key={a.name}>
              <th>{a.name}</th>
              <td data-testid={`pos-${a.name}`}>{(motion.positions?.[a.name] ?? 0).toFixed(a.unit === "mm" ? 1 : 3)} {a.unit}</td>
              <td class="small">{a.min_pos} .. {a.max_pos}</td>
              <td>
                <input aria-label={`${a.name} target (${a.unit})`} data-testid={`target-${a.name}`} size={7}
                  value={targets[a.name] ?? ""} onInput={(e) => setTargets({ ...targets, [a.name]: (e.target as HTMLInputElement).value })} />
                <button data-testid={`go-${a.name}`} onClick={() => go({ [FIELDS[a.name]]: Number(targets[a.name]) })}>go</button>
              </td>
              <td>
                {[-1, 1].map((s) => (
                  <button key={s} onClick={() => go({ [FIELDS[a.name]]: (motion.positions?.[a.name] ?? 0) + s * (a.unit === "mm" ? 100 : 1) })}>
                    {s < 0 ? "−" : "+"}{a.unit === "mm" ? "100 mm" : "1°"}
                  </button>
                ))}
              </td>
            </tr>
          ))}
        </tbody>
      </table>
    </section>
  );
}
