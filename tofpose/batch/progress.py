"""The client's side of a run's progress: frames done by its finished tasks (from their
results) and by its running ones (from the events they log while they run,
``tofpose.batch.worker.ProgressReporter``), so that progress moves within a chunk, not
only at its end."""

from __future__ import annotations

import threading
import uuid


class RunProgress:
    """Subscribed to a topic of its own on ``client`` while open (a context manager):
    ``topic`` goes to the tasks, ``running_frames()`` adds up what the running tasks
    reported last, ``finished(key)`` drops a task whose result is in (a report that
    arrives after it is ignored)."""

    def __init__(self, client) -> None:
        self.client = client
        self.topic = f"tofpose-progress-{uuid.uuid4().hex}"
        self._running: dict[str, int] = {}
        self._finished: set[str] = set()
        self._lock = threading.Lock()
        self.events = 0

    def __enter__(self) -> RunProgress:
        self.client.subscribe_topic(self.topic, self._on_event)
        return self

    def __exit__(self, *exc) -> None:
        self.client.unsubscribe_topic(self.topic)

    def _on_event(self, event) -> None:
        """``event``: (time, {"key", "frames"}) as ``Worker.log_event`` sent it."""
        _, msg = event
        with self._lock:
            self.events += 1
            if msg["key"] not in self._finished:
                self._running[msg["key"]] = max(self._running.get(msg["key"], 0), msg["frames"])

    def finished(self, key: str) -> None:
        with self._lock:
            self._finished.add(key)
            self._running.pop(key, None)

    def running_frames(self) -> int:
        with self._lock:
            return sum(self._running.values())
