"""The campaign repository on an SQLite file: what it stores and reads back, the state
changes a person's commands make (checked against the transition table), the queue's
order, recovery after a crash, and a set-point committed whole."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import numpy as np
import pytest

from backend.db.engine import make_engine, make_session_factory, upgrade_database
from backend.drivers.base import CameraFrame
from backend.services.campaigns.campaign_repository import CampaignNotFoundError, CampaignRepository
from backend.services.campaigns.campaign_states import (
    CampaignCommand,
    CampaignState,
    CampaignTransitionError,
)
from backend.services.live.acquisition import LiveSample
from tofpose.pipeline import PoseResult

C = CampaignCommand


@pytest.fixture
def repo(tmp_path) -> CampaignRepository:
    engine = make_engine(f"sqlite:///{tmp_path / 'db.sqlite'}")
    upgrade_database(engine)
    yield CampaignRepository(make_session_factory(engine))
    engine.dispose()


def _create(repo: CampaignRepository, name: str = "grid", **kw):
    kw.setdefault("setpoints", [{"yaw": 0.0, "rail": 11000.0}, {"yaw": 5.0}, {}])
    return repo.create(
        name=name,
        catalog_name="paper-target",
        frames_per_point=3,
        settle_s=0.5,
        lock_timeout_s=5.0,
        requirements={"x_mm": 6.0},
        **kw,
    )


def _sample(index: int) -> LiveSample:
    frame = CameraFrame(
        np.zeros((2, 2), np.uint16),
        np.zeros((2, 2), np.float32),
        0.1 * index,
        index,
        meta={"encoders": {"yaw": 5.0}},
    )
    return LiveSample(frame, PoseResult(False, "no blobs", 0.1 * index), "paper-target", 0.0, 0.0)


def test_a_created_campaign_reads_back_as_a_draft_with_its_setpoints(repo):
    made = _create(repo)
    got = repo.get(made.id)
    assert got == made
    assert got.status is CampaignState.DRAFT and got.status_reason == ""
    assert [sp.axes for sp in got.setpoints] == [{"yaw": 0.0, "rail": 11000.0}, {"yaw": 5.0}, {}]
    assert [sp.index for sp in got.pending] == [0, 1, 2] and got.n_done == 0
    assert got.catalog == "paper-target" and got.camera is None  # the API's names
    assert repo.exists(made.id) and not repo.exists(made.id + 1)
    with pytest.raises(CampaignNotFoundError, match=f"no campaign with id {made.id + 1}"):
        repo.get(made.id + 1)


def test_the_view_reads_the_columns_its_fields_rename(repo):
    """``catalog`` and ``camera`` (the API's names) come from the row's ``catalog_name``
    and ``camera_settings``."""
    made = repo.create(
        name="with camera",
        catalog_name="first-four",
        setpoints=[{}],
        frames_per_point=1,
        settle_s=0.0,
        lock_timeout_s=1.0,
        requirements={},
        camera={"integration_time_us": 500},
    )
    got = repo.get(made.id)
    assert (got.catalog, got.camera) == ("first-four", {"integration_time_us": 500})


def test_the_list_is_newest_first_with_every_setpoint(repo):
    ids = [_create(repo, f"c{i}").id for i in range(3)]
    listed = repo.list()
    assert [c.id for c in listed] == ids[::-1]
    assert all(len(c.setpoints) == 3 for c in listed)


def test_commands_change_the_stored_state_as_the_table_says(repo):
    cid = _create(repo).id
    at = datetime(2030, 1, 2, 3, 4, tzinfo=UTC)
    assert repo.apply(cid, C.START, scheduled_at=at) is CampaignState.QUEUED
    assert repo.get(cid).scheduled_at == at
    assert repo.apply(cid, C.PAUSE, reason="paused by request") is CampaignState.PAUSED
    assert repo.get(cid).status_reason == "paused by request"
    assert repo.apply(cid, C.RESUME) is CampaignState.QUEUED
    c = repo.get(cid)
    assert c.scheduled_at is None and c.status_reason == "" and c.finished_at is None
    assert repo.apply(cid, C.CANCEL, reason="cancelled by request") is CampaignState.CANCELLED
    assert repo.get(cid).finished_at is not None
    with pytest.raises(CampaignTransitionError, match=f"campaign {cid} is already cancelled"):
        repo.apply(cid, C.CANCEL)
    assert repo.get(cid).status is CampaignState.CANCELLED  # a refusal changes nothing
    with pytest.raises(CampaignNotFoundError):
        repo.apply(cid + 1, C.START)


def test_the_queue_runs_unscheduled_campaigns_first_then_those_due(repo):
    now = datetime.now(UTC)
    later, due, first, second = (_create(repo, n).id for n in ("later", "due", "a", "b"))
    repo.apply(later, C.START, scheduled_at=now + timedelta(hours=1))
    repo.apply(due, C.START, scheduled_at=now - timedelta(minutes=1))
    assert repo.next_due(now) == due
    repo.apply(second, C.START)
    repo.apply(first, C.START)
    assert repo.next_due(now) == first  # by id among the unscheduled
    for cid in (first, second, due):
        repo.set_status(cid, CampaignState.RUNNING)
    assert repo.next_due(now) is None
    assert repo.next_due(now + timedelta(hours=2)) == later


def test_recover_interrupts_what_a_dead_server_left_running(repo):
    running, done = _create(repo, "r").id, _create(repo, "d").id
    for cid in (running, done):
        repo.apply(cid, C.START)
        assert repo.set_status(cid, CampaignState.RUNNING)
    assert repo.set_status(done, CampaignState.DONE)
    started = repo.get(running).started_at
    assert repo.recover() == (1, 0)
    c = repo.get(running)
    assert c.status is CampaignState.INTERRUPTED and "server stopped" in c.status_reason
    assert c.started_at == started and repo.get(done).status is CampaignState.DONE
    assert repo.get(done).finished_at is not None


def test_recover_holds_every_queued_campaign_until_a_person_resumes_it(repo):
    """No motion after a restart without a person: queued campaigns (due now or
    scheduled) are paused with a reason that says why; drafts and finished ones stay."""
    now = datetime(2026, 12, 6, 7, 0, tzinfo=UTC)
    queued, scheduled, draft = (_create(repo, n).id for n in ("q", "s", "d"))
    repo.apply(queued, C.START)
    repo.apply(scheduled, C.START, scheduled_at=now + timedelta(hours=3))
    assert repo.recover(now) == (0, 2)
    for cid in (queued, scheduled):
        c = repo.get(cid)
        assert c.status is CampaignState.PAUSED
        assert c.status_reason.startswith("held at server start (2026-12-06 07:00:00 UTC)")
    assert repo.get(draft).status is CampaignState.DRAFT
    assert repo.next_due(now + timedelta(days=1)) is None  # the scheduler finds nothing
    repo.apply(queued, C.RESUME)
    assert repo.next_due(now) == queued


def test_a_setpoint_is_stored_whole_with_its_recording_indices(repo):
    c = _create(repo)
    sp = c.setpoints[1]
    repo.store_setpoint(sp.id, [(_sample(k), None) for k in range(3)], first_recording_index=6)
    got = repo.get(c.id)
    assert [s.status for s in got.setpoints] == ["pending", "done", "pending"]
    assert got.n_done == 1 and [s.index for s in got.pending] == [0, 2]
    assert repo.committed_frames(c.id) == 3
    total, page = repo.measurements(c.id, offset=1, limit=10)
    assert total == 3 and [(m.frame_index, i) for m, i in page] == [(1, 1), (2, 1)]
    assert [m.recording_index for m, _ in page] == [7, 8]
    assert page[0][0].encoders == {"yaw": 5.0} and page[0][0].reason == "no blobs"
    with pytest.raises(CampaignNotFoundError):
        repo.measurements(c.id + 1, 0, 10)


def test_a_setpoint_that_fails_to_store_stores_nothing(repo):
    c = _create(repo)
    sp = c.setpoints[0]
    twice = [(_sample(1), None), (_sample(1), None)]  # the same frame twice: unique index
    with pytest.raises(Exception, match="UNIQUE"):
        repo.store_setpoint(sp.id, twice)
    assert repo.committed_frames(c.id) == 0 and repo.get(c.id).setpoints[0].status == "pending"


def test_the_runner_never_takes_a_paused_or_cancelled_campaign_back_to_running(repo):
    """``set_status`` makes only the runner's transitions from the stored state: a
    campaign a person paused or cancelled after the scheduler picked it stays so (the
    pick-then-claim race that let a cancelled campaign move the table)."""
    paused, cancelled, queued = (_create(repo, n).id for n in ("p", "c", "q"))
    for cid in (paused, cancelled, queued):
        repo.apply(cid, C.START)
    repo.apply(paused, C.PAUSE, reason="paused by request")
    repo.apply(cancelled, C.CANCEL)
    assert not repo.set_status(paused, CampaignState.RUNNING)
    assert not repo.set_status(cancelled, CampaignState.RUNNING)
    assert repo.get(paused).status is CampaignState.PAUSED
    assert repo.get(paused).status_reason == "paused by request"
    assert repo.get(cancelled).status is CampaignState.CANCELLED
    assert repo.get(paused).started_at is None
    assert repo.set_status(queued, CampaignState.RUNNING)  # the one still queued is taken
    assert not repo.set_status(queued, CampaignState.QUEUED)  # not a runner's transition
    assert repo.get(queued).status is CampaignState.RUNNING
