// The audit trail (admin keys only; GET /api/audit): every state-changing request, who
// sent it (the key's name), from where, what, and what the server answered. Loaded when
// opened and on "refresh", never polled in the background (a page without an admin key
// would only collect 403s).
import { useState } from "preact/hooks";
import { api, unwrap } from "../api/client";
import { usePolling } from "../polling";

function AuditTable() {
  const entries = usePolling(() => unwrap(api.GET("/api/audit", { params: { query: { limit: 50 } } })), null);
  if (entries.error) return <p class="small warn" data-testid="audit-error">{entries.error} (the audit trail needs an admin key)</p>;
  const list = entries.data;
  if (!list) return <p class="small">loading</p>;
  return (
    <>
      <button data-testid="audit-refresh" onClick={entries.refresh}>refresh</button>
      <table data-testid="audit" class="small">
        <thead><tr><th>time</th><th>key</th><th>client</th><th>request</th><th>answer</th><th>body</th></tr></thead>
        <tbody>
          {list.map((e) => (
            <tr key={e.id}>
              <td>{new Date(e.at).toLocaleString()}</td>
              <td>{e.key_name ?? "(none)"}</td>
              <td>{e.client}</td>
              <td>{e.method} {e.path}</td>
              <td class={e.status >= 400 ? "warn" : ""}>{e.status}</td>
              <td><code>{e.body}</code></td>
            </tr>
          ))}
        </tbody>
      </table>
    </>
  );
}

export function AuditLog() {
  const [open, setOpen] = useState(false);
  return (
    <section class="card">
      <h2>Audit trail <button data-testid="audit-toggle" aria-expanded={open} onClick={() => setOpen(!open)}>{open ? "hide" : "show"}</button></h2>
      {open ? <AuditTable /> : <p class="small">who moved what and when: every command, with its key's name (admin key)</p>}
    </section>
  );
}
