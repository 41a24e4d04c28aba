// The campaign list with status, progress and report downloads.
import { useEffect, useState } from "preact/hooks";
import { api, type Campaign } from "../api/client";

export function Campaigns({ onError }: { onError: (m: string | null) => void }) {
  const [list, setList] = useState<Campaign[]>([]);
  useEffect(() => {
    const poll = () => api<Campaign[]>("GET", "/api/campaigns").then(setList).catch((e) => onError(e.message));
    poll();
    const t = window.setInterval(poll, 2000);
    return () => window.clearInterval(t);
  }, []);
  return (
    <section class="card">
      <h2>Campaigns</h2>
      {list.length === 0 ? <p class="small">none yet (POST /api/campaigns; see docs/campaigns.md)</p> : (
        <table>
          <thead><tr><th>id</th><th>name</th><th>status</th><th>set-points</th><th>report</th></tr></thead>
          <tbody>
            {list.map((c) => (
              <tr key={c.id}>
                <td>{c.id}</td><td>{c.name}</td>
                <td>{c.status}{c.status_reason ? `: ${c.status_reason}` : ""}</td>
                <td>{c.n_done} / {c.n_setpoints}</td>
                <td>{(["html", "pdf", "csv", "json"] as const).map((f) => (
                  <a key={f} href={`/api/campaigns/${c.id}/report.${f}`}>{f} </a>
                ))}</td>
              </tr>
            ))}
          </tbody>
        </table>
      )}
    </section>
  );
}
