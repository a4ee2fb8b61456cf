"""A consumer's wait for its producer (``_loop/_wakeup.py``): on both loops
:meth:`Wakeup.set` resumes the waiter, a time limit ends the wait without an
error, a set with nobody waiting does nothing, and a cancellation from
outside ends the wait. On trio (``_loop/_trio_wakeup.py``) the deadline ends the
wait with a plain return, not a ``Cancelled`` raised and caught, and a
cancellation from outside is never lost; trio's virtual clock (``MockClock``,
jumping ahead whenever every task waits) makes those times exact, so the
tests assert them."""

from __future__ import annotations

import sys

import pytest

trio = pytest.importorskip("trio")
trio_testing = pytest.importorskip("trio.testing")

import anyio  # noqa: E402

from ros_mobile_bridge._loop._trio_wakeup import TrioWakeup  # noqa: E402
from ros_mobile_bridge._loop._wakeup import new_wakeup  # noqa: E402


def run(fn: object) -> None:
    trio.run(fn, clock=trio_testing.MockClock(autojump_threshold=0))


async def sleep(seconds: float) -> None:
    await TrioWakeup().wait(seconds)


async def sleep_until(deadline: float) -> None:
    await sleep(deadline - trio.current_time())


async def test_set_resumes_the_waiter_and_only_it() -> None:
    wakeup = new_wakeup()
    wakeup.set()  # nobody waits: nothing happens, and the next wait still waits
    order: list[str] = []

    async def waiter() -> None:
        await wakeup.wait()
        order.append("woken")

    async with anyio.create_task_group() as tg:
        tg.start_soon(waiter)
        await anyio.wait_all_tasks_blocked()
        assert order == []
        order.append("set")
        wakeup.set()
        wakeup.set()  # twice: the waiter is resumed once
    assert order == ["set", "woken"]


async def test_a_time_limit_ends_the_wait_without_an_error() -> None:
    wakeup = new_wakeup()
    start = anyio.current_time()
    await wakeup.wait(0.05)
    assert anyio.current_time() - start >= 0.04
    wakeup.set()  # after the wait ended: nothing to resume
    with anyio.move_on_after(0.05) as scope:
        await wakeup.wait()  # and it waits again
    assert scope.cancelled_caught


async def test_set_before_the_time_limit_ends_the_wait_early() -> None:
    wakeup = new_wakeup()
    ended: list[float] = []

    async def waiter() -> None:
        start = anyio.current_time()
        await wakeup.wait(30.0)
        ended.append(anyio.current_time() - start)

    with anyio.fail_after(5):
        async with anyio.create_task_group() as tg:
            tg.start_soon(waiter)
            await anyio.wait_all_tasks_blocked()
            wakeup.set()
    assert ended and ended[0] < 5.0


async def test_a_cancellation_from_outside_ends_the_wait() -> None:
    wakeup = new_wakeup()
    for limit in (None, 30.0):
        with anyio.move_on_after(0.05) as scope:
            await wakeup.wait(limit)
        assert scope.cancelled_caught
        wakeup.set()  # the cancelled waiter is gone: nothing to resume


def test_trio_the_deadline_ends_the_wait_with_a_return() -> None:
    seen: list[object] = []

    async def main() -> None:
        start = trio.current_time()
        with trio.CancelScope() as outer:
            await sleep_until(start + 2.5)
            seen.append(trio.current_time() - start)
            seen.append(sys.exc_info()[1])  # no exception in flight
            await sleep(0.5)
            seen.append(trio.current_time() - start)
        seen.append(outer.cancelled_caught)

    run(main)
    assert seen == [2.5, None, 3.0, False]


def test_trio_a_deadline_already_past_returns_at_once() -> None:
    seen: list[float] = []

    async def main() -> None:
        start = trio.current_time()
        await sleep_until(start - 1.0)
        await sleep(0.0)
        seen.append(trio.current_time() - start)

    run(main)
    assert seen == [0.0]


def test_trio_a_cancellation_from_outside_raises_cancelled() -> None:
    seen: list[object] = []

    async def main() -> None:
        start = trio.current_time()
        with trio.move_on_after(1.0) as outer:
            await sleep(10.0)
            seen.append("not cancelled")
        seen.append((outer.cancelled_caught, trio.current_time() - start))
        async with trio.open_nursery() as nursery:  # by another task

            async def sleeper() -> None:
                try:
                    await sleep(10.0)
                except trio.Cancelled:
                    seen.append(("cancelled", trio.current_time() - start))
                    raise

            nursery.start_soon(sleeper)
            await trio.sleep(2.0)
            nursery.cancel_scope.cancel()

    run(main)
    assert seen == [(True, 1.0), ("cancelled", 3.0)]


def test_trio_a_cancellation_at_the_deadline_is_not_lost() -> None:
    """Another task cancels the sleeper's scope at the sleeper's own deadline:
    whichever of the two comes first, the sleeper is cancelled at the latest
    at its next checkpoint, and never passes it."""
    outcomes: list[str] = []

    async def canceller(deadline: float, scope: trio.CancelScope) -> None:
        await trio.sleep_until(deadline)
        scope.cancel()

    async def sleeper(deadline: float) -> None:
        try:
            await sleep_until(deadline)
        except trio.Cancelled:
            outcomes.append("cancelled in the sleep")
            raise
        try:
            await trio.lowlevel.checkpoint()
        except trio.Cancelled:
            outcomes.append("cancelled at the next checkpoint")
            raise
        outcomes.append("lost")

    async def main() -> None:
        for _ in range(20):
            deadline = trio.current_time() + 1.0
            async with trio.open_nursery() as nursery:
                nursery.start_soon(canceller, deadline, nursery.cancel_scope)
                nursery.start_soon(sleeper, deadline)

    run(main)
    assert len(outcomes) == 20
    assert "lost" not in outcomes, outcomes
