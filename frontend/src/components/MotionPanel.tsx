// Axis positions, go-to within the soft limits, jog, and an always-visible STOP (in the
// header). Nothing reaches the motion system that the user did not type: a go-to sends
// only a complete number inside the axis' soft limits (an empty or partial field says
// what is wrong and sends nothing), a jog is a relative step the server applies to the
// axis' encoder position when it arrives (POST /api/motion/jog), every control waits for
// its answer before it can be used again (a double click sends one move), and the
// controls are locked while the turntable's status is stale or a campaign owns it. STOP
// latches on the server: the panel says so and offers the release (POST
// /api/motion/release), which is the only way back to moving by hand.
import { useState } from "preact/hooks";
import { api, unwrap, type Motion, type Schemas } from "../api/client";
import { reported, useReportError } from "../errors";
import { usePolling } from "../polling";
import { parseSetpoint } from "../setpoint";

type Move = Schemas["MoveRequest"];
type Jog = Schemas["JogRequest"];
// The request field of each axis (the same in a move and a jog).
const FIELDS: Record<string, keyof Move & keyof Jog> = { yaw: "yaw_deg", pitch: "pitch_deg", roll: "roll_deg", rail: "rail_mm" };
const STALE_AFTER_MS = 2000;

/** Why the motion controls are locked, or null when they can be used. */
function lockReason(motion: Motion, updatedAt: number, now: number): string | null {
  if (now - updatedAt > STALE_AFTER_MS) return "turntable status is stale (no answer for 2 s): controls locked";
  if (motion.stop_latched)
    return `STOP pressed${latchedAt(motion)} holds the turntable: nothing moves until it is released`;
  if (motion.owner_campaign_id !== null && motion.owner_campaign_id !== undefined)
    return `campaign ${motion.owner_campaign_id} ("${motion.owner_campaign_name}") owns the turntable: pause or cancel it to move by hand`;
  if (motion.state === "absent") return "no motion system";
  if (motion.state !== "ok" || Object.keys(motion.positions ?? {}).length === 0)
    return `turntable status unknown (${motion.state}${motion.last_error ? `: ${motion.last_error}` : ""}): controls locked`;
  return null;
}

/** " at HH:MM:SS" (local time) of the latched STOP, or "". */
function latchedAt(motion: Motion): string {
  return motion.stop_latched_at ? ` at ${new Date(motion.stop_latched_at).toLocaleTimeString()}` : "";
}

export function MotionPanel() {
  const report = useReportError();
  // `clock`: the panel re-renders every 500 ms even when no answer comes (a dropped link
  // locks the controls after 2 s)
  const polled = usePolling(() => unwrap(api.GET("/api/motion")), 500, { clock: true });
  const [targets, setTargets] = useState<Record<string, string>>({});
  const [fieldErrors, setFieldErrors] = useState<Record<string, string>>({});
  const [pending, setPending] = useState<string | null>(null);
  const send = async (key: string, command: () => Promise<Motion>) => {
    if (pending !== null) return; // one command at a time: a double click sends one
    setPending(key);
    try {
      const m = await reported(report, command);
      if (m) polled.set(m);
    } finally {
      setPending(null);
    }
  };
  const motion = polled.data;
  if (!motion) return <section class="card"><h2>Turntable</h2><p>loading</p></section>;
  const locked = lockReason(motion, polled.updatedAt, polled.now);
  // `typed`: the field's text when the form is submitted (read from the input itself, so
  // an Enter that arrives before the re-render still sends what is in the field)
  const goTo = (axis: Motion["axes"][number], typed: string) => {
    if (locked) {
      setFieldErrors({ ...fieldErrors, [axis.name]: `not sent: ${locked}` });
      return;
    }
    const parsed = parseSetpoint(typed, axis);
    if ("error" in parsed) {
      setFieldErrors({ ...fieldErrors, [axis.name]: parsed.error });
      return;
    }
    setFieldErrors({ ...fieldErrors, [axis.name]: "" });
    const body: Move = {};
    body[FIELDS[axis.name]] = parsed.value;
    send(`go-${axis.name}`, () => unwrap(api.POST("/api/motion/move", { body })));
  };
  return (
    <section class="card">
      <h2>Turntable <span class="small">{motion.busy ? "moving" : motion.settled ? "settled" : "settling"}</span></h2>
      {locked && <p class="small warn" data-testid="motion-locked">{locked}</p>}
      {motion.stop_latched && (
        <p class="latched" data-testid="stop-latched">
          <strong>STOP latched</strong>
          <button data-testid="release-stop" disabled={pending !== null}
            title="let motion commands through again (a campaign STOP paused stays paused until resumed)"
            onClick={() => send("release", () => unwrap(api.POST("/api/motion/release")))}>release STOP</button>
        </p>
      )}
      <table class="axes">
        <thead><tr><th>axis</th><th>position</th><th>limits</th><th>go to</th><th>jog</th></tr></thead>
        <tbody>
          {motion.axes.map((a) => {
            const pos = motion.positions?.[a.name];
            const err = fieldErrors[a.name];
            const step = a.unit === "mm" ? 100 : 1;
            return (
              <tr key={a.name}>
                <th>{a.name}</th>
                <td data-testid={`pos-${a.name}`}>{pos === undefined ? "-" : pos.toFixed(a.unit === "mm" ? 1 : 3)} {a.unit}</td>
                <td class="small">{a.min_pos} .. {a.max_pos}</td>
                <td>
                  <form class="goto" onSubmit={(e) => {
                    e.preventDefault();
                    const input = (e.currentTarget as HTMLFormElement).querySelector("input");
                    goTo(a, input?.value ?? targets[a.name] ?? "");
                  }}>
                    <input aria-label={`${a.name} target (${a.unit})`} data-testid={`target-${a.name}`} size={7}
                      inputMode="decimal" aria-invalid={err ? "true" : undefined}
                      aria-describedby={err ? `target-error-${a.name}` : undefined}
                      // a disabled "go" blocks the form's Enter: say why here instead
                      onKeyDown={(e) => { if (e.key === "Enter" && locked) goTo(a, ""); }}
                      value={targets[a.name] ?? ""} onInput={(e) => {
                        setTargets({ ...targets, [a.name]: (e.target as HTMLInputElement).value });
                        if (err) setFieldErrors({ ...fieldErrors, [a.name]: "" });
                      }} />
                    <button type="submit" data-testid={`go-${a.name}`} disabled={!!locked || pending !== null}>go</button>
                    {err && <span class="field-error" role="alert" id={`target-error-${a.name}`} data-testid={`target-error-${a.name}`}>{err}</span>}
                  </form>
                </td>
                <td>
                  {[-1, 1].map((s) => (
                    <button key={s} data-testid={`jog-${a.name}-${s < 0 ? "minus" : "plus"}`}
                      disabled={!!locked || pending !== null || motion.busy}
                      title={`move ${a.name} by ${s * step} ${a.unit} from where it is now`}
                      onClick={() => {
                        const body: Jog = {};
                        body[FIELDS[a.name]] = s * step;
                        send(`jog-${a.name}`, () => unwrap(api.POST("/api/motion/jog", { body })));
                      }}>
                      {s < 0 ? "−" : "+"}{a.unit === "mm" ? "100 mm" : "1°"}
                    </button>
                  ))}
                </td>
              </tr>
            );
          })}
        </tbody>
      </table>
    </section>
  );
}
