import gc
import threading
import time

import pytest

from tofpose.io.read_ahead import THREAD_NAME, ReadAhead, cores_available


def _reader_threads() -> list[threading.Thread]:
    return [t for t in threading.enumerate() if t.name.startswith(THREAD_NAME)]


class _Log:
    """A read that records which spans were asked for and which finished; ``fail_at``:
    the span start whose read raises; ``pause_s``: how long each read takes."""

    def __init__(self, fail_at: int | None = None, pause_s: float = 0.0) -> None:
        self.started: list[int] = []
        self.finished: list[int] = []
        self.fail_at = fail_at
        self.pause_s = pause_s

    def __call__(self, a: int, b: int) -> list[int]:
        self.started.append(a)
        time.sleep(self.pause_s)
        if a == self.fail_at:
            raise ValueError(f"span {a}..{b} is unreadable")
        self.finished.append(a)
        return list(range(a, b))


SPANS = [(0, 3), (3, 6), (6, 8)]


def test_blocks_come_in_order_and_the_thread_ends_with_them():
    log = _Log()
    reader = ReadAhead(log, SPANS)
    assert reader.running
    assert list(reader) == [[0, 1, 2], [3, 4, 5], [6, 7]]
    assert not reader.running and not _reader_threads()
    assert log.finished == [0, 3, 6]


def test_the_next_block_is_read_while_the_caller_holds_this_one_and_no_further():
    log = _Log()
    with ReadAhead(log, SPANS) as reader:
        assert next(reader) == [0, 1, 2]
        reader._pending.result()  # the read ahead, done without the caller asking
        assert log.started == [0, 3]  # one ahead, not two
        assert next(reader) == [3, 4, 5]
    assert not _reader_threads()


def test_a_failed_read_raises_in_the_caller_at_its_block_and_stops_the_thread():
    log = _Log(fail_at=3)
    reader = ReadAhead(log, SPANS)
    assert next(reader) == [0, 1, 2]
    with pytest.raises(ValueError, match="span 3..6 is unreadable"):
        next(reader)
    assert not reader.running and not _reader_threads()
    assert log.started == [0, 3]  # nothing read after the failure
    with pytest.raises(StopIteration):
        next(reader)


def test_closing_early_waits_for_the_read_in_flight_and_starts_no_other():
    log = _Log(pause_s=0.05)
    reader = ReadAhead(log, SPANS)
    assert next(reader) == [0, 1, 2]  # the read of 3..6 is under way (or queued)
    reader.close()
    assert not reader.running and not _reader_threads()
    assert log.finished == log.started  # whatever began, ended before close returned
    assert 6 not in log.started
    reader.close()  # a second close does nothing
    with pytest.raises(StopIteration):
        next(reader)


def test_a_caller_that_drops_the_iterator_stops_the_thread():
    log = _Log(pause_s=0.01)
    reader = ReadAhead(log, SPANS)
    next(reader)
    del reader
    gc.collect()
    assert not _reader_threads()
    assert log.finished == log.started


def test_no_spans_no_thread():
    reader = ReadAhead(_Log(), [])
    assert not reader.running and list(reader) == []


def test_cores_available_counts_at_least_one():
    assert cores_available() >= 1
