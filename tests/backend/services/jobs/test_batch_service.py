"""The batch job services' common part: which stored jobs a start queues again, the queue
owned or shared, and the cluster arguments."""

from __future__ import annotations

import threading
from collections.abc import Callable

from backend.services.jobs.batch_queue import BatchQueue
from backend.services.jobs.batch_service import WORKER_NICENESS, BatchJobService
from tests.backend.conftest import wait_for


class Countdown(BatchJobService):
    """A job per directory whose ``todo`` file exists; a run records its id."""

    kind = "countdown"

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.ran: list[int] = []
        self.done = threading.Event()

    def _requeue(self, jid: int) -> bool:
        return (self._dir(jid) / "todo").exists()

    def _run_one(self, jid: int, should_stop: Callable[[], bool]) -> None:
        self.ran.append(jid)
        if len(self.ran) == 2:
            self.done.set()


def _store(root, todo: list[int], finished: list[int]) -> None:
    for jid in todo + finished:
        (root / str(jid)).mkdir(parents=True)
    for jid in todo:
        (root / str(jid) / "todo").write_text("")
    (root / "notes").mkdir()  # not a job: its name is no id


def test_start_queues_again_what_the_subclass_accepts_in_id_order_and_runs_it(tmp_path):
    _store(tmp_path / "jobs", todo=[10, 2], finished=[3])
    service = Countdown(tmp_path / "jobs", workers=1)
    assert service.start() == 2
    try:
        wait_for(service.done.is_set, what="both jobs")
        assert service.ran == [2, 10]
    finally:
        service.stop()


def test_start_makes_the_root_and_queues_nothing_in_a_new_one(tmp_path):
    service = Countdown(tmp_path / "new", workers=1)
    assert service.start() == 0
    service.stop()
    assert (tmp_path / "new").is_dir()


def test_a_shared_queue_is_neither_started_nor_stopped_by_the_service(tmp_path):
    _store(tmp_path / "jobs", todo=[1, 2], finished=[])
    shared = BatchQueue()
    service = Countdown(tmp_path / "jobs", workers=1, jobs=shared)
    assert service.start() == 2
    service.stop()
    assert service.ran == []  # queued, but the queue's owner has not started it
    shared.start()
    try:
        wait_for(service.done.is_set, what="both jobs on the shared queue")
        assert service.ran == [1, 2]
    finally:
        shared.stop()


def test_the_cluster_is_the_scheduler_or_a_local_one_at_low_priority(tmp_path):
    local = Countdown(tmp_path, workers=3)
    assert local._cluster() == {"workers": 3, "scheduler": None, "niceness": WORKER_NICENESS}
    remote = Countdown(tmp_path, scheduler="tcp://lab:8786", workers=3)
    assert remote._cluster() == {"workers": None, "scheduler": "tcp://lab:8786", "niceness": 0}
    assert Countdown(tmp_path, scheduler="", workers=3).scheduler is None
    assert remote._key(7) == ("countdown", 7)
