import { describe, expect, it } from "vitest";
import { commandsIn, isFinished, type CampaignStates } from "./campaignStates";

const TABLE: CampaignStates = {
  states: ["draft", "queued", "running", "paused", "interrupted", "done", "failed", "cancelled"],
  finished: ["done", "failed", "cancelled"],
  transitions: [
    { command: "start", from_state: "draft", to_state: "queued" },
    { command: "cancel", from_state: "draft", to_state: "cancelled" },
    { command: "start", from_state: "queued", to_state: "queued" },
    { command: "cancel", from_state: "queued", to_state: "cancelled" },
    { command: "pause", from_state: "running", to_state: "paused" },
    { command: "cancel", from_state: "running", to_state: "cancelled" },
    { command: "resume", from_state: "paused", to_state: "queued" },
    { command: "resume", from_state: "paused", to_state: "queued" },
  ],
};

describe("commandsIn", () => {
  it("lists each command the table allows in a state once, in the table's order", () => {
    expect(commandsIn(TABLE, "draft")).toEqual(["start", "cancel"]);
    expect(commandsIn(TABLE, "running")).toEqual(["pause", "cancel"]);
    expect(commandsIn(TABLE, "paused")).toEqual(["resume"]);
  });

  it("does not offer a command that leaves the state as it is", () => {
    expect(commandsIn(TABLE, "queued")).toEqual(["cancel"]);
  });

  it("offers nothing in a finished state, or before the table has loaded", () => {
    expect(commandsIn(TABLE, "done")).toEqual([]);
    expect(commandsIn(null, "draft")).toEqual([]);
  });
});

describe("isFinished", () => {
  it("is the table's list of states nothing leads out of", () => {
    expect(isFinished(TABLE, "cancelled")).toBe(true);
    expect(isFinished(TABLE, "paused")).toBe(false);
    expect(isFinished(undefined, "done")).toBe(false);
  });
});
