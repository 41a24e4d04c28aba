"""Fan-out of live samples to many subscribers without ever blocking the publisher.

Each subscriber has a small bounded buffer; when it is full the *oldest* item is dropped
and counted (``dropped``; a subscription made with ``on_drop`` also reports each drop
there: the live WebSocket clients' drops go to the latency statistics,
``backend.services.live.latency``). The publisher (the acquisition thread) only appends
to deques and, for asyncio subscribers, schedules a wake-up on their event loop.
"""

from __future__ import annotations

import asyncio
import threading
from collections import deque
from collections.abc import Callable
from typing import Any


class Subscription:
    """A bounded, drop-oldest mailbox usable from threads (``get``) or asyncio
    (``get_async``, when created with a loop)."""

    def __init__(
        self,
        maxsize: int,
        loop: asyncio.AbstractEventLoop | None = None,
        *,
        label: str | None = None,
        on_drop: Callable[[int], None] | None = None,
    ) -> None:
        self._items: deque[Any] = deque(maxlen=maxsize)
        self.label = label  # who reads it (a WebSocket client's address), None: internal
        self._on_drop = on_drop
        self._cond = threading.Condition()
        self._loop = loop
        self._event = asyncio.Event() if loop is not None else None
        self.dropped = 0
        self.offered = 0
        self.closed = False

    def offer(self, item: Any) -> None:
        """Called by the publisher; never blocks for long."""
        with self._cond:
            full = len(self._items) == self._items.maxlen
            if full:
                self.dropped += 1
            self._items.append(item)
            self.offered += 1
            self._cond.notify()
        if full and self._on_drop is not None:
            self._on_drop(1)
        if self._loop is not None and self._event is not None:
            try:
                self._loop.call_soon_threadsafe(self._event.set)
            except RuntimeError:  # the subscriber's loop is closed
                self.closed = True

    @property
    def pending(self) -> int:
        """Items waiting to be read."""
        with self._cond:
            return len(self._items)

    def _pop(self) -> Any | None:
        with self._cond:
            return self._items.popleft() if self._items else None

    def get(self, timeout_s: float | None = None) -> Any | None:
        """Next item, waiting up to ``timeout_s``; None on timeout."""
        with self._cond:
            if not self._items:
                self._cond.wait(timeout_s)
            return self._items.popleft() if self._items else None

    async def get_async(self) -> Any:
        if self._event is None:
            raise RuntimeError("subscription was created without an event loop")
        while True:
            self._event.clear()
            item = self._pop()
            if item is not None:
                return item
            await self._event.wait()


class LiveHub:
    """Registry of subscriptions; ``publish`` hands an item to each of them."""

    def __init__(self, default_maxsize: int = 8) -> None:
        self.default_maxsize = default_maxsize
        self._subs: set[Subscription] = set()
        self._lock = threading.Lock()

    def subscribe(
        self,
        maxsize: int | None = None,
        loop: asyncio.AbstractEventLoop | None = None,
        *,
        label: str | None = None,
        on_drop: Callable[[int], None] | None = None,
    ) -> Subscription:
        """A new mailbox; ``label`` names its reader, ``on_drop(n)`` is told of each drop
        (called on the publisher's thread, outside the mailbox's lock)."""
        sub = Subscription(maxsize or self.default_maxsize, loop, label=label, on_drop=on_drop)
        with self._lock:
            self._subs.add(sub)
        return sub

    def unsubscribe(self, sub: Subscription) -> None:
        with self._lock:
            self._subs.discard(sub)

    def subscriptions(self) -> list[Subscription]:
        """A snapshot of the current subscriptions (for status and tests)."""
        with self._lock:
            return list(self._subs)

    @property
    def n_subscribers(self) -> int:
        with self._lock:
            return len(self._subs)

    def publish(self, item: Any) -> None:
        with self._lock:
            subs = list(self._subs)
        for sub in subs:
            sub.offer(item)
            if sub.closed:
                self.unsubscribe(sub)
