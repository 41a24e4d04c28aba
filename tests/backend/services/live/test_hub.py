"""The live hub: bounded, drop-oldest mailboxes; the publisher never blocks."""

from __future__ import annotations

import asyncio
import threading

from backend.services.live.hub import LiveHub


def test_a_slow_subscriber_keeps_the_newest_items_and_counts_the_rest():
    hub = LiveHub(default_maxsize=4)
    sub = hub.subscribe()
    for i in range(10_000):  # would block forever if publish waited for the reader
        hub.publish(i)
    assert sub.dropped == 10_000 - 4
    assert [sub.get(0.0) for _ in range(5)] == [9996, 9997, 9998, 9999, None]


def test_every_subscriber_gets_every_item_when_it_keeps_up():
    hub = LiveHub(default_maxsize=2)
    subs = [hub.subscribe() for _ in range(3)]
    got = [[] for _ in subs]
    for i in range(50):
        hub.publish(i)
        for s, g in zip(subs, got, strict=True):
            g.append(s.get(0.0))
    assert all(g == list(range(50)) for g in got)
    hub.unsubscribe(subs[0])
    hub.publish(99)
    assert subs[0].get(0.0) is None and subs[1].get(0.0) == 99


def test_async_subscriber_is_woken_from_another_thread():
    hub = LiveHub()

    async def main():
        sub = hub.subscribe(loop=asyncio.get_running_loop())
        threading.Thread(target=lambda: [hub.publish(i) for i in range(3)]).start()
        return [await asyncio.wait_for(sub.get_async(), 2.0) for _ in range(3)]

    assert asyncio.run(main()) == [0, 1, 2]


def test_subscribers_whose_loop_is_gone_are_removed():
    hub = LiveHub()
    loop = asyncio.new_event_loop()
    sub = hub.subscribe(loop=loop)
    loop.close()
    hub.publish(1)
    assert sub.closed and hub.n_subscribers == 0
