"""A campaign's states and the commands that move it between them (docs/campaigns.md,
"States"): the one table the service, the API document and the dashboard read.

A person's commands (``TRANSITIONS``): ``start`` queues a draft (or re-schedules a queued
campaign), ``pause`` stops a queued or running one, ``resume`` queues a paused or
interrupted one again, ``cancel`` ends anything not finished. What happens on its own
(``RUNNER_TRANSITIONS``): the scheduler runs a queued campaign; the runner leaves a
running one done, failed, paused (a request, STOP, a device fault, a lost pose lock),
cancelled, or interrupted (the server stopped).
"""

from __future__ import annotations

from enum import StrEnum


class CampaignState(StrEnum):
    """Where a campaign is in its life (stored as this text in ``campaigns.status``)."""

    DRAFT = "draft"
    QUEUED = "queued"
    RUNNING = "running"
    PAUSED = "paused"
    INTERRUPTED = "interrupted"
    DONE = "done"
    FAILED = "failed"
    CANCELLED = "cancelled"


class CampaignCommand(StrEnum):
    """What a person asks of a campaign (``POST /api/campaigns/{id}/{command}``)."""

    START = "start"
    PAUSE = "pause"
    RESUME = "resume"
    CANCEL = "cancel"


S, C = CampaignState, CampaignCommand
TRANSITIONS: dict[CampaignState, dict[CampaignCommand, CampaignState]] = {
    S.DRAFT: {C.START: S.QUEUED, C.CANCEL: S.CANCELLED},
    S.QUEUED: {C.START: S.QUEUED, C.PAUSE: S.PAUSED, C.CANCEL: S.CANCELLED},
    S.RUNNING: {C.PAUSE: S.PAUSED, C.CANCEL: S.CANCELLED},
    S.PAUSED: {C.RESUME: S.QUEUED, C.CANCEL: S.CANCELLED},
    S.INTERRUPTED: {C.RESUME: S.QUEUED, C.CANCEL: S.CANCELLED},
    S.DONE: {},
    S.FAILED: {},
    S.CANCELLED: {},
}
"""state -> {command -> the state it leads to}; a command not listed is refused (409)."""

RUNNER_TRANSITIONS: dict[CampaignState, frozenset[CampaignState]] = {
    S.QUEUED: frozenset({S.RUNNING}),
    S.RUNNING: frozenset({S.DONE, S.FAILED, S.PAUSED, S.CANCELLED, S.INTERRUPTED}),
}
"""What the scheduler and the runner do without a command (and a server that starts
after one died mid-campaign: running -> interrupted)."""
del S, C

FINISHED = frozenset(s for s, commands in TRANSITIONS.items() if not commands)
"""done, failed, cancelled: nothing leads out of them."""
RESUMABLE = frozenset(s for s, c in TRANSITIONS.items() if CampaignCommand.RESUME in c)

_DONE_TO = {
    CampaignCommand.START: "started",
    CampaignCommand.PAUSE: "paused",
    CampaignCommand.RESUME: "resumed",
    CampaignCommand.CANCEL: "cancelled",
}
_HINTS = {CampaignCommand.START: " (resume a paused or interrupted one)"}


class CampaignConflictError(RuntimeError):
    """The request conflicts with the campaign's state or with another campaign."""


class CampaignTransitionError(CampaignConflictError):
    """``command`` is not allowed in ``state`` (``TRANSITIONS``)."""

    def __init__(self, message: str, state: CampaignState, command: CampaignCommand) -> None:
        super().__init__(message)
        self.state = state
        self.command = command


def allowed_from(command: CampaignCommand) -> list[CampaignState]:
    """The states in which ``command`` is accepted, in the order of ``CampaignState``."""
    return [s for s in CampaignState if command in TRANSITIONS[s]]


def check_transition(
    state: CampaignState | str, command: CampaignCommand | str, campaign_id: int | None = None
) -> CampaignState:
    """The state ``command`` leads to from ``state``; ``CampaignTransitionError`` naming
    the campaign, its state and the states the command needs when it is not allowed."""
    state, command = CampaignState(state), CampaignCommand(command)
    to = TRANSITIONS[state].get(command)
    if to is not None:
        return to
    who = "the campaign" if campaign_id is None else f"campaign {campaign_id}"
    if command is CampaignCommand.CANCEL and state in FINISHED:
        message = f"{who} is already {state}"
    else:
        states = " or ".join(allowed_from(command))
        message = f"{who} is {state}: only a {states} campaign can be {_DONE_TO[command]}"
        message += _HINTS.get(command, "")
        if command is CampaignCommand.RESUME and state is CampaignState.DONE:
            message += "; it has nothing left to do"
    raise CampaignTransitionError(message, state, command)


def transition_table() -> list[tuple[CampaignState, CampaignCommand, CampaignState]]:
    """Every allowed (from, command, to), states in enum order, commands in theirs."""
    return [(s, c, to) for s in CampaignState for c, to in TRANSITIONS[s].items()]
