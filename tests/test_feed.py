"""flow's event streams (:class:`Feed`) and the watcher of a value once it
is known (:class:`Present`): what ``watch_server_status``,
``watch_server_time`` and ``watch_playback`` are made of."""

from __future__ import annotations

import gc

import anyio
import pytest

from ros_mobile_bridge.flow import Feed, Present, Watchable


async def test_every_watcher_gets_every_event_published_after_it_was_made() -> None:
    feed: Feed[int] = Feed()
    feed.publish(0)  # before any watcher: nobody gets it
    first = feed.watch()
    feed.publish(1)
    second = feed.watch()
    feed.publish(2)
    feed.close()
    assert [e async for e in first] == [1, 2]
    assert [e async for e in second] == [2]
    assert [e async for e in feed.watch()] == []  # made after the close: ends at once


async def test_a_watcher_behind_its_backlog_loses_the_oldest_and_counts_them() -> None:
    feed: Feed[int] = Feed(backlog=3)
    watcher = feed.watch()
    for i in range(10):
        feed.publish(i)
    feed.close()
    assert [e async for e in watcher] == [7, 8, 9]
    assert watcher.dropped == 7


async def test_a_waiting_watcher_wakes_on_the_next_event() -> None:
    feed: Feed[str] = Feed()
    watcher = feed.watch()
    got: list[str] = []

    async def read() -> None:
        got.append(await watcher.__anext__())

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(read)
            await anyio.wait_all_tasks_blocked()
            assert got == []
            feed.publish("hello")
    assert got == ["hello"]


def test_a_dropped_watcher_is_forgotten() -> None:
    feed: Feed[int] = Feed()
    feed.watch()
    gc.collect()
    assert len(feed._watchers) == 0
    with pytest.raises(ValueError, match="backlog"):
        Feed(backlog=0)


async def test_present_waits_out_none_and_yields_the_values() -> None:
    value: Watchable[int | None] = Watchable(None)
    seen: list[int] = []

    async def watch() -> None:
        async for v in Present(value):
            seen.append(v)

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(watch)
            await anyio.wait_all_tasks_blocked()
            assert seen == []  # None is not yielded
            value.set(5)
            await anyio.wait_all_tasks_blocked()
            value.set(None)
            value.set(6)
            await anyio.wait_all_tasks_blocked()
            value.close()
    assert seen == [5, 6]
