"""Reports and exports on workers of their own with a bounded queue: at most ``workers``
jobs at once, ``max_waiting`` waiting, the rest refused at once."""

from __future__ import annotations

import threading

import anyio
import pytest

from backend.services.heavy_work import HeavyWork, HeavyWorkBusyError


def test_at_most_workers_run_and_the_queue_beyond_is_refused_at_once():
    heavy = HeavyWork(workers=2, max_waiting=1)
    release = threading.Event()
    running = 0
    peak = 0
    lock = threading.Lock()

    def job() -> int:
        nonlocal running, peak
        with lock:
            running += 1
            peak = max(peak, running)
        release.wait(5.0)
        with lock:
            running -= 1
        return 7

    results: list[int] = []
    refused: list[str] = []

    async def submit() -> None:
        try:
            results.append(await heavy.run(job, "a report"))
        except HeavyWorkBusyError as exc:
            refused.append(str(exc))

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            for _ in range(5):
                tg.start_soon(submit)
            with anyio.fail_after(5):
                while len(refused) < 2 or heavy.admitted < 3:
                    await anyio.sleep(0.01)
            release.set()

    anyio.run(main)
    assert results == [7, 7, 7] and peak == 2  # two at a time, the third waited its turn
    assert len(refused) == 2 and "a report was not started" in refused[0]
    assert heavy.admitted == 0


def test_a_job_error_reaches_the_caller_and_frees_its_place():
    heavy = HeavyWork(workers=1, max_waiting=0)

    def boom() -> None:
        raise ValueError("no such campaign")

    async def main() -> int:
        with pytest.raises(ValueError, match="no such campaign"):
            await heavy.run(boom, "x")
        return await heavy.run(lambda: 3, "y")

    assert anyio.run(main) == 3


def test_bad_sizes_are_refused():
    with pytest.raises(ValueError, match="workers must be >= 1"):
        HeavyWork(workers=0)
