"""The trio-only sleep of read coalescing (``transport/_trio_io.py``): its
deadline ends it with a plain return, not a ``Cancelled`` raised and caught,
and a cancellation from outside is never lost. trio's virtual clock
(``MockClock``, jumping ahead whenever every task waits) makes the times
exact, so the tests assert them."""

from __future__ import annotations

import sys

import pytest

trio = pytest.importorskip("trio")
trio_testing = pytest.importorskip("trio.testing")

from ros_mobile_bridge.transport import _trio_io  # noqa: E402


def run(fn: object) -> None:
    trio.run(fn, clock=trio_testing.MockClock(autojump_threshold=0))


def test_the_deadline_ends_the_sleep_with_a_return() -> None:
    seen: list[object] = []

    async def main() -> None:
        start = trio.current_time()
        with trio.CancelScope() as outer:
            await _trio_io.sleep_until(start + 2.5)
            seen.append(trio.current_time() - start)
            seen.append(sys.exc_info()[1])  # no exception in flight
            await _trio_io.sleep(0.5)
            seen.append(trio.current_time() - start)
        seen.append(outer.cancelled_caught)

    run(main)
    assert seen == [2.5, None, 3.0, False]


def test_a_deadline_already_past_returns_at_once() -> None:
    seen: list[float] = []

    async def main() -> None:
        start = trio.current_time()
        await _trio_io.sleep_until(start - 1.0)
        await _trio_io.sleep(0.0)
        seen.append(trio.current_time() - start)

    run(main)
    assert seen == [0.0]


def test_a_cancellation_from_outside_raises_cancelled() -> None:
    seen: list[object] = []

    async def main() -> None:
        start = trio.current_time()
        with trio.move_on_after(1.0) as outer:
            await _trio_io.sleep(10.0)
            seen.append("not cancelled")
        seen.append((outer.cancelled_caught, trio.current_time() - start))
        async with trio.open_nursery() as nursery:  # by another task

            async def sleeper() -> None:
                try:
                    await _trio_io.sleep(10.0)
                except trio.Cancelled:
                    seen.append(("cancelled", trio.current_time() - start))
                    raise

            nursery.start_soon(sleeper)
            await trio.sleep(2.0)
            nursery.cancel_scope.cancel()

    run(main)
    assert seen == [(True, 1.0), ("cancelled", 3.0)]


def test_a_cancellation_at_the_deadline_is_not_lost() -> None:
    """Another task cancels the sleeper's scope at the sleeper's own deadline:
    whichever of the two comes first, the sleeper is cancelled at the latest
    at its next checkpoint, and never passes it."""
    outcomes: list[str] = []

    async def canceller(deadline: float, scope: trio.CancelScope) -> None:
        await trio.sleep_until(deadline)
        scope.cancel()

    async def sleeper(deadline: float) -> None:
        try:
            await _trio_io.sleep_until(deadline)
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
