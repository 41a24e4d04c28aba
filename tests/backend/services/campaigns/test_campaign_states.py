"""The campaign state machine: every allowed transition leads where docs/campaigns.md
says, every other command is refused with a sentence naming the campaign, its state and
what the command needs."""

from __future__ import annotations

import itertools

import pytest

from backend.services.campaigns.campaign_states import (
    FINISHED,
    RESUMABLE,
    RUNNER_TRANSITIONS,
    TRANSITIONS,
    CampaignCommand,
    CampaignConflictError,
    CampaignState,
    CampaignTransitionError,
    check_transition,
    transition_table,
)

S, C = CampaignState, CampaignCommand
# docs/campaigns.md, "States", written out by hand: (from, command) -> to
ALLOWED = {
    (S.DRAFT, C.START): S.QUEUED,
    (S.DRAFT, C.CANCEL): S.CANCELLED,
    (S.QUEUED, C.START): S.QUEUED,  # re-scheduled (another ``at``, or now)
    (S.QUEUED, C.PAUSE): S.PAUSED,
    (S.QUEUED, C.CANCEL): S.CANCELLED,
    (S.RUNNING, C.PAUSE): S.PAUSED,
    (S.RUNNING, C.CANCEL): S.CANCELLED,
    (S.PAUSED, C.RESUME): S.QUEUED,
    (S.PAUSED, C.CANCEL): S.CANCELLED,
    (S.INTERRUPTED, C.RESUME): S.QUEUED,
    (S.INTERRUPTED, C.CANCEL): S.CANCELLED,
}
FORBIDDEN = [pair for pair in itertools.product(S, C) if pair not in ALLOWED]


@pytest.mark.parametrize(("state", "command"), list(ALLOWED))
def test_every_allowed_transition_leads_where_the_docs_say(state, command):
    assert check_transition(state, command) is ALLOWED[state, command]
    assert check_transition(state.value, command.value, 7) is ALLOWED[state, command]


def test_the_table_is_the_documented_one_and_lists_each_transition_once():
    assert {(a, c): b for a, c, b in transition_table()} == ALLOWED
    assert len(transition_table()) == len(ALLOWED)
    assert set(TRANSITIONS) == set(S)


@pytest.mark.parametrize(("state", "command"), FORBIDDEN)
def test_every_other_command_is_refused_naming_the_campaign_state_and_command(state, command):
    with pytest.raises(CampaignTransitionError) as info:
        check_transition(state, command, 12)
    err = info.value
    assert isinstance(err, CampaignConflictError)  # the API answers 409
    assert (err.state, err.command) == (state, command)
    text = str(err)
    assert text.startswith("campaign 12 is ") and state.value in text


@pytest.mark.parametrize(
    ("state", "command", "message"),
    [
        (
            S.RUNNING,
            C.START,
            "campaign 3 is running: only a draft or queued campaign can be "
            "started (resume a paused or interrupted one)",
        ),
        (
            S.DONE,
            C.RESUME,
            "campaign 3 is done: only a paused or interrupted campaign can be "
            "resumed; it has nothing left to do",
        ),
        (
            S.FAILED,
            C.RESUME,
            "campaign 3 is failed: only a paused or interrupted campaign can be resumed",
        ),
        (
            S.PAUSED,
            C.PAUSE,
            "campaign 3 is paused: only a queued or running campaign can be paused",
        ),
        (
            S.DRAFT,
            C.RESUME,
            "campaign 3 is draft: only a paused or interrupted campaign can be resumed",
        ),
        (S.CANCELLED, C.CANCEL, "campaign 3 is already cancelled"),
        (S.DONE, C.CANCEL, "campaign 3 is already done"),
    ],
)
def test_the_refusals_read_as_sentences(state, command, message):
    with pytest.raises(CampaignTransitionError) as info:
        check_transition(state, command, 3)
    assert str(info.value) == message


def test_without_an_id_the_message_says_the_campaign():
    with pytest.raises(CampaignTransitionError, match="^the campaign is done: only a draft"):
        check_transition("done", "start")


def test_an_unknown_state_or_command_is_a_value_error_not_a_refusal():
    with pytest.raises(ValueError, match="'sleeping' is not a valid CampaignState"):
        check_transition("sleeping", "start")
    with pytest.raises(ValueError, match="'restart' is not a valid CampaignCommand"):
        check_transition("draft", "restart")


def test_finished_and_resumable_states_come_from_the_table():
    assert {S.DONE, S.FAILED, S.CANCELLED} == FINISHED
    assert {S.PAUSED, S.INTERRUPTED} == RESUMABLE
    for state in FINISHED:
        assert TRANSITIONS[state] == {} and state not in RUNNER_TRANSITIONS


def test_only_the_runner_makes_a_campaign_run_and_ends_a_run():
    assert not any(to is S.RUNNING for _, _, to in transition_table())
    assert RUNNER_TRANSITIONS[S.QUEUED] == {S.RUNNING}
    assert RUNNER_TRANSITIONS[S.RUNNING] == {S.DONE, S.FAILED, S.PAUSED, S.CANCELLED, S.INTERRUPTED}
