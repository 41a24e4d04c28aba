// Which lab reference the live error is measured against: the nominal lab geometry
// (uncalibrated: the bench's own mount and placement errors are part of the error shown)
// or a stored calibration, selectable here; from the nominal one, a calibration campaign
// is one click away (it fills the new-campaign form).
import { useEffect, useRef, useState } from "preact/hooks";
import { api } from "../api/client";
import type { components } from "../api/schema";

type Reference = components["schemas"]["ReferencePublic"];
type Calibration = components["schemas"]["CalibrationPublic"];

export function ReferenceBar({ onCalibrate, onError }: { onCalibrate: () => void; onError: (m: string | null) => void }) {
  const [ref, setRef] = useState<Reference | null>(null);
  const [cals, setCals] = useState<Calibration[]>([]);
  const [busy, setBusy] = useState(false);
  const changes = useRef(0); // a poll that started before the last change is out of date
  const poll = () => {
    const asked = changes.current;
    api<Reference>("GET", "/api/reference").then((r) => {
      if (asked !== changes.current) return;
      setRef(r);
      if (r.n_calibrations !== cals.length) api<Calibration[]>("GET", "/api/calibrations").then(setCals).catch(() => {});
    }).catch((e) => onError(String(e.message)));
  };
  useEffect(() => {
    poll();
    const t = window.setInterval(poll, 3000);
    return () => window.clearInterval(t);
  }, [cals.length]);
  if (!ref) return null;
  const select = async (value: string) => {
    setBusy(true);
    changes.current += 1;
    try {
      setRef(await api<Reference>("PUT", "/api/reference", { calibration_id: value === "" ? null : Number(value) }));
      onError(null);
    } catch (e) {
      onError((e as Error).message);
    } finally {
      setBusy(false);
    }
  };
  return (
    <div class="small reference" data-testid="reference">
      reference: <strong data-testid="reference-label">{ref.label}</strong>
      {ref.source === "nominal" && (
        <span data-testid="reference-warning"> — the error shown includes the bench's own mount and placement errors
          {ref.calibrated_available && <> <button data-testid="reference-calibrate" onClick={onCalibrate}>set up a calibration campaign</button></>}
        </span>
      )}
      {cals.length > 0 && (
        <label> use <select data-testid="reference-select" disabled={busy} value={ref.calibration_id ?? ""}
          onChange={(e) => select((e.target as HTMLSelectElement).value)}>
          <option value="">nominal lab geometry</option>
          {cals.map((c) => <option key={c.id} value={c.id}>calibration {c.id} ({c.name})</option>)}
        </select></label>
      )}
    </div>
  );
}
