// Which lab reference the live error is measured against: the nominal lab geometry
// (uncalibrated: the bench's own mount and placement errors are part of the error shown)
// or a stored calibration, selectable here; from the nominal one, a calibration campaign
// is one click away (it fills the new-campaign form).
import { useEffect, useState } from "preact/hooks";
import { api, unwrap, type Schemas } from "../api/client";
import { reported, useReportError } from "../errors";
import { usePolling } from "../polling";

type Calibration = Schemas["CalibrationPublic"];

export function ReferenceBar({ onCalibrate }: { onCalibrate: () => void }) {
  const report = useReportError();
  const reference = usePolling(() => unwrap(api.GET("/api/reference")), 3000);
  const [cals, setCals] = useState<Calibration[]>([]);
  const [busy, setBusy] = useState(false);
  const ref = reference.data;
  // the list of calibrations, fetched again whenever the reference counts another number
  useEffect(() => {
    if (ref && ref.n_calibrations !== cals.length)
      unwrap(api.GET("/api/calibrations")).then(setCals).catch(() => {});
  }, [ref]);
  if (!ref) return null;
  const select = async (value: string) => {
    setBusy(true);
    reference.invalidate(); // a poll sent before this change would show the old reference
    try {
      const changed = await reported(report, () =>
        unwrap(api.PUT("/api/reference", { body: { calibration_id: value === "" ? null : Number(value) } })));
      if (changed) reference.set(changed);
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
