"""Read the next block while the caller works on this one: one reader thread, one
block ahead.

``ReadAhead(read, spans)`` iterates ``read(a, b)`` over ``spans`` in order, calling it
for the next span in a background thread while the caller holds the current block.
The reader's exception is raised in the caller, at the block it belongs to. Closing
(explicitly, at the end of the spans, or when the caller stops iterating and drops it)
cancels what has not started and waits for the read in flight, so the file may be
closed right after; a reader never outlives its ``ReadAhead`` by more than one read.

The overlap is real only where the read runs without the GIL and a second core is
free to run it (``cores_available`` says how many this process may use). h5py
releases the GIL inside HDF5's read (decompression included) but holds its own lock
meanwhile: the caller's work overlaps a read as long as it makes no h5py call of its
own, which would wait for the read in flight.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Generic, TypeVar

T = TypeVar("T")

THREAD_NAME = "tofpose-read-ahead"


def cores_available() -> int:
    """CPU cores this process may run on (its affinity where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


class ReadAhead(Generic[T]):
    """Iterator over ``read(a, b)`` for each ``(a, b)`` of ``spans``, one read ahead in a
    reader thread. Use as a context manager, or let it run to the end."""

    def __init__(self, read: Callable[[int, int], T], spans: Sequence[tuple[int, int]]) -> None:
        self._read = read
        self._spans = list(spans)
        self._next = 0  # index into spans of the block the caller gets next
        self._pool: ThreadPoolExecutor | None = None
        self._pending: Future[T] | None = None
        if self._spans:
            self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix=THREAD_NAME)
            self._pending = self._pool.submit(self._read, *self._spans[0])

    @property
    def running(self) -> bool:
        """Whether a reader thread is still there (closed, or at the end: False)."""
        return self._pool is not None

    def __iter__(self) -> Iterator[T]:
        return self

    def __next__(self) -> T:
        if self._pending is None:
            self.close()
            raise StopIteration
        try:
            block = self._pending.result()
        except BaseException:
            self.close()
            raise
        self._next += 1
        if self._next < len(self._spans) and self._pool is not None:
            self._pending = self._pool.submit(self._read, *self._spans[self._next])
        else:
            self._pending = None
            self.close()
        return block

    def close(self) -> None:
        """Cancel the read not yet started, wait for the one in flight, end the thread.
        Idempotent."""
        pending, pool = self._pending, self._pool
        self._pending, self._pool = None, None
        if pending is not None:
            pending.cancel()
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)

    def __enter__(self) -> ReadAhead[T]:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __del__(self) -> None:
        self.close()
