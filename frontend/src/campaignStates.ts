// The campaign state machine as the server serves it (GET /api/campaigns/states): which
// commands a person may give a campaign in each state. The dashboard reads the table
// instead of keeping its own copy of the states.
import type { components } from "./api/schema";

export type CampaignState = components["schemas"]["CampaignState"];
export type CampaignCommand = components["schemas"]["CampaignCommand"];
export type CampaignStates = components["schemas"]["CampaignStatesPublic"];

/** The commands that move a campaign out of ``state``, in the table's order, without
 * repeats (a command the table accepts but that leaves the state as it is, such as
 * start on a queued campaign, is not offered). */
export function commandsIn(table: CampaignStates | null | undefined, state: CampaignState): CampaignCommand[] {
  if (!table) return [];
  const out: CampaignCommand[] = [];
  for (const t of table.transitions) {
    if (t.from_state === state && t.to_state !== state && !out.includes(t.command)) out.push(t.command);
  }
  return out;
}

/** Whether nothing leads out of ``state`` (done, failed, cancelled). */
export function isFinished(table: CampaignStates | null | undefined, state: CampaignState): boolean {
  return table?.finished.includes(state) ?? false;
}
