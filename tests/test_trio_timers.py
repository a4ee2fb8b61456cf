"""trio's shared timer of timed waits (``_loop/_trio_timers.py``, and the heap's
side of ``_loop/_trio_wakeup.py``): a coarse wait ends on the loop's one runner, no
earlier than asked and at most ``GRID`` later; an exact one at its deadline;
neither enters a cancel scope (the runner's one scope is moved on, never
expired); waits due in the same millisecond end in one wake-up; a wait's
callback (``then``) runs at the deadline instead of the task, and may keep
it waiting; a wait that ended early leaves no trap for the next; an outside
cancellation still raises; with nobody running the heap a wait keeps its
own cancel scope; when the last participant leaves, every waiter is
resumed; another participant takes over from one that leaves; and the heap
is bounded. trio only: on asyncio a loop timer is cheap and every wait is
exact (``serve_timers`` returns at once, as the last test checks on both
loops). trio's virtual clock (``MockClock``, jumping ahead whenever every
task waits) makes the times exact."""

from __future__ import annotations

import contextlib
import logging
import math
from collections.abc import AsyncIterator

import pytest

trio = pytest.importorskip("trio")
trio_testing = pytest.importorskip("trio.testing")

import anyio  # noqa: E402
import sniffio  # noqa: E402

from ros_mobile_bridge._loop import _trio_timers  # noqa: E402
from ros_mobile_bridge._loop._trio_timers import (  # noqa: E402
    COMPACT_ABOVE,
    GRID,
    Entry,
    TrioTimers,
    current_timers,
)
from ros_mobile_bridge._loop._trio_wakeup import TrioWakeup  # noqa: E402
from ros_mobile_bridge._loop._wakeup import serve_timers  # noqa: E402


def run(fn: object) -> None:
    trio.run(fn, clock=trio_testing.MockClock(autojump_threshold=0))


class Runner:
    """A participant running the loop's timers, in its own cancel scope."""

    def __init__(self, nursery: trio.Nursery) -> None:
        self.scope = trio.CancelScope()
        nursery.start_soon(self._run)

    async def _run(self) -> None:
        with self.scope:
            await current_timers().participate()


@contextlib.asynccontextmanager
async def running_timers() -> AsyncIterator[None]:
    """A participant runs the loop's timers for the block (it leaves at the
    block's end)."""
    async with trio.open_nursery() as nursery:
        runner = Runner(nursery)
        await trio.testing.wait_all_tasks_blocked()
        yield
        runner.scope.cancel()


async def coarse_wait(timeout: float, ends: list[float]) -> None:
    await TrioWakeup().wait(timeout, coarse=True)
    ends.append(trio.current_time())


def test_a_coarse_wait_ends_on_the_runner_no_earlier_and_at_most_a_grid_later() -> None:
    async def main() -> None:
        timers = current_timers()
        async with trio.open_nursery() as nursery:
            runner = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            assert timers.running
            start = trio.current_time()
            ends: list[float] = []
            await coarse_wait(0.2503, ends)
            assert 0.2503 <= ends[0] - start <= 0.2503 + GRID + 1e-9
            assert timers.fired == 1
            runner.scope.cancel()

    run(main)


def test_waits_due_in_the_same_millisecond_end_in_one_wake_up() -> None:
    async def main() -> None:
        timers = current_timers()
        async with trio.open_nursery() as nursery:
            runner = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            base = math.ceil(trio.current_time() / GRID) * GRID - trio.current_time()
            ends: list[float] = []
            async with trio.open_nursery() as waiters:
                for i in range(100):  # all due within one grid step
                    waiters.start_soon(coarse_wait, base + 0.1 + GRID * (0.1 + i / 200), ends)
            assert len(ends) == 100
            assert len(set(ends)) == 1
            assert timers.wakeups == 1
            assert timers.fired == 100
            runner.scope.cancel()

    run(main)


def test_an_exact_wait_ends_on_the_heap_at_its_deadline_with_no_scope_of_its_own() -> None:
    async def main() -> None:
        timers = current_timers()
        async with running_timers():
            wakeup = TrioWakeup()
            for timeout in (0.0043, 0.0007, 0.25):  # not on the grid
                start = trio.current_time()
                await wakeup.wait(timeout)
                assert trio.current_time() - start == pytest.approx(timeout, abs=1e-9)
            assert timers.fired == 3
            # the runner's one scope was moved on each time, never expired
            assert timers.rearmed == 0

    run(main)


def test_without_the_instrument_the_runners_own_scope_still_ends_every_wait(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """Should trio expire the runner's scope before the instrument moves it
    on (its deadline passing between the two clock readings; here: the
    instrument does nothing), the runner resumes the waiters itself."""
    monkeypatch.setattr(_trio_timers._AfterIoWait, "after_io_wait", lambda self, timeout: None)

    async def main() -> None:
        timers = current_timers()
        async with running_timers():
            wakeup = TrioWakeup()
            for timeout in (0.0043, 0.25):
                start = trio.current_time()
                await wakeup.wait(timeout)
                assert trio.current_time() - start == pytest.approx(timeout, abs=1e-9)
            assert (timers.fired, timers.rearmed) == (2, 2)

    run(main)


def test_a_waits_callback_runs_at_the_deadline_and_may_keep_the_task_waiting() -> None:
    async def main() -> None:
        timers = current_timers()
        async with running_timers():
            wakeup = TrioWakeup()
            start = trio.current_time()
            calls: list[float] = []
            answers = [(0.5, False), (0.25, True), (0.0, False)]

            def then() -> tuple[float, bool]:
                calls.append(round(trio.current_time() - start, 6))
                return answers[len(calls) - 1]

            await wakeup.wait(1.0, then=then)
            # called at 1.0, 1.5 and (coarse) at 1.75 rounded up; the task
            # resumed only after the last, which asked for no more
            assert calls[:2] == [pytest.approx(1.0), pytest.approx(1.5)]
            assert 1.75 <= calls[2] <= 1.75 + GRID + 1e-9
            assert trio.current_time() - start == pytest.approx(calls[2], abs=1e-9)
            assert (timers.fired, timers.rearmed) == (3, 0)

    run(main)


def test_a_set_ends_a_wait_its_callback_wanted_to_go_on() -> None:
    async def main() -> None:
        async with running_timers():
            wakeup = TrioWakeup()
            start = trio.current_time()

            def then() -> tuple[float, bool]:
                wakeup.set()  # (what a delivery ending a hold does)
                return 10.0, False

            await wakeup.wait(0.5, then=then)
            assert trio.current_time() - start == pytest.approx(0.5)
            # and nothing of it is left to end the next wait early
            await wakeup.wait(2.0)
            assert trio.current_time() - start == pytest.approx(2.5)

    run(main)


def test_a_callback_that_raises_is_logged_and_the_task_resumes(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def main() -> None:
        timers = current_timers()
        async with running_timers():
            wakeup = TrioWakeup()

            def then() -> tuple[float, bool]:
                raise RuntimeError("a bug in the callback")

            start = trio.current_time()
            with caplog.at_level(logging.ERROR, logger="ros_mobile_bridge._loop._trio_wakeup"):
                await wakeup.wait(0.3, then=then)
            assert trio.current_time() - start == pytest.approx(0.3)
            assert "a timed wait's callback failed" in caplog.text
            # the loop's timer still works (trio drops an instrument that raises)
            await wakeup.wait(0.2, coarse=True)
            assert timers.fired == 2

    run(main)


def test_a_callback_is_not_called_without_a_runner_nor_for_a_cancelled_wait() -> None:
    async def main() -> None:
        called: list[str] = []

        def then() -> tuple[float, bool]:
            called.append("called")
            return 0.0, False

        start = trio.current_time()
        await TrioWakeup().wait(0.1, then=then)  # no runner: its own scope
        assert trio.current_time() - start == pytest.approx(0.1)
        ended: list[float] = []

        async def wait_long() -> None:
            await TrioWakeup().wait(5.0, then=then)
            ended.append(trio.current_time())

        async with trio.open_nursery() as nursery:
            async with running_timers():
                with trio.move_on_after(0.1):
                    await TrioWakeup().wait(0.5, then=then)
                await trio.sleep(1.0)  # past the cancelled wait's deadline
                nursery.start_soon(wait_long)
                await trio.testing.wait_all_tasks_blocked()
                left = trio.current_time()
            # the last participant left: the long wait resumed, not called
        assert ended == [pytest.approx(left)]
        assert called == []

    run(main)


def test_a_wait_ended_early_does_not_end_the_next_one_early() -> None:
    async def main() -> None:
        async with trio.open_nursery() as nursery:
            runner = Runner(nursery)
            wakeup = TrioWakeup()
            ends: list[float] = []

            async def waiter() -> None:
                await wakeup.wait(1.0, coarse=True)  # ended at 0.1 by set()
                ends.append(trio.current_time())
                await wakeup.wait(5.0, coarse=True)  # its old entry fires at 1.0
                ends.append(trio.current_time())
                await wakeup.wait(0.5, coarse=True)  # earlier than the entry at 5.1
                ends.append(trio.current_time())
                await wakeup.wait(2.0)  # exact; the 5.1 entry stays on the heap
                ends.append(trio.current_time())
                await wakeup.wait()  # untimed
                ends.append(trio.current_time())

            start = trio.current_time()
            nursery.start_soon(waiter)
            await trio.sleep(0.1)
            wakeup.set()
            await trio.sleep(8.0)  # past every entry's deadline
            wakeup.set()
            await trio.testing.wait_all_tasks_blocked()
            got = [round(t - start, 6) for t in ends]
            assert got[0] == pytest.approx(0.1)
            assert 5.1 <= got[1] <= 5.1 + GRID + 1e-9
            assert got[1] + 0.5 <= got[2] <= got[1] + 0.5 + GRID + 1e-9
            assert got[3] == pytest.approx(got[2] + 2.0)
            assert got[4] == pytest.approx(8.1)
            runner.scope.cancel()

    run(main)


def test_a_cancellation_from_outside_still_raises() -> None:
    async def main() -> None:
        async with trio.open_nursery() as nursery:
            runner = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            wakeup = TrioWakeup()
            with trio.move_on_after(0.3) as scope:
                await wakeup.wait(10.0, coarse=True)
            assert scope.cancelled_caught
            start = trio.current_time()
            await wakeup.wait(20.0, coarse=True)  # the 10 s entry does not end it
            assert trio.current_time() - start >= 20.0
            runner.scope.cancel()

    run(main)


def test_with_nobody_running_the_heap_a_coarse_wait_keeps_its_own_scope() -> None:
    async def main() -> None:
        timers = current_timers()
        assert not timers.running
        start = trio.current_time()
        await TrioWakeup().wait(0.25, coarse=True)
        assert trio.current_time() - start == pytest.approx(0.25)
        assert (timers.fired, len(timers)) == (0, 0)

    run(main)


def test_when_the_last_participant_leaves_every_waiter_is_resumed() -> None:
    async def main() -> None:
        timers = current_timers()
        async with trio.open_nursery() as nursery:
            runner = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            ends: list[float] = []
            start = trio.current_time()
            for timeout in (30.0, 60.0):
                nursery.start_soon(coarse_wait, timeout, ends)
            await trio.sleep(1.0)
            assert ends == []
            runner.scope.cancel()  # the last (only) participant leaves
            await trio.testing.wait_all_tasks_blocked()
            assert [t - start for t in ends] == [pytest.approx(1.0)] * 2
            assert (timers.running, timers.participants, len(timers)) == (False, 0, 0)

    run(main)


def test_another_participant_takes_over_the_heap() -> None:
    async def main() -> None:
        timers = current_timers()
        async with trio.open_nursery() as nursery:
            first = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            second = Runner(nursery)
            await trio.testing.wait_all_tasks_blocked()
            assert timers.participants == 2
            ends: list[float] = []
            start = trio.current_time()
            nursery.start_soon(coarse_wait, 3.0, ends)
            await trio.sleep(1.0)
            first.scope.cancel()  # the running one leaves: the second runs the heap
            await trio.sleep(5.0)
            assert [t - start for t in ends] == [pytest.approx(3.0, abs=GRID)]
            assert timers.running
            assert timers.fired == 1
            second.scope.cancel()

    run(main)


class Owner:
    """A waiter on the heap that only ever owns its newest entry."""

    def __init__(self) -> None:
        self.entry: Entry | None = None
        self.expired: list[Entry] = []

    def owns(self, entry: Entry) -> bool:
        return entry is self.entry

    def expire(self, entry: Entry, now: float) -> None:
        self.expired.append(entry)


def test_the_heap_is_rebuilt_without_replaced_entries_above_its_bound() -> None:
    async def main() -> None:
        timers = TrioTimers()
        owner = Owner()
        most = 0
        for i in range(3 * COMPACT_ABOVE):
            owner.entry = timers.push(1000.0 - i * GRID, owner)  # each earlier
            most = max(most, len(timers))
        assert most == COMPACT_ABOVE
        timers.release_all()  # (the newest entry was kept: it expires)
        assert owner.expired and owner.entry in owner.expired
        assert len(timers) == 0

    run(main)


def test_a_rebuild_keeps_every_live_entry_however_many() -> None:
    async def main() -> None:
        timers = TrioTimers()
        owners = [Owner() for _ in range(3 * COMPACT_ABOVE)]
        for i, owner in enumerate(owners):
            owner.entry = timers.push(1000.0 + (i + 0.5) * GRID, owner)
        assert len(timers) == len(owners)  # rebuilds at 4096 and 8192 dropped none
        timers.expire_due(1000.0 + 10.5 * GRID)  # the first ten are due
        assert sum(1 for owner in owners if owner.expired) == 10
        timers.release_all()
        assert all(owner.expired == [owner.entry] for owner in owners)

    run(main)


# -- on both loops ------------------------------------------------------------------------


async def test_serve_timers_runs_the_heap_on_trio_only() -> None:
    if sniffio.current_async_library() != "trio":
        with anyio.fail_after(5):
            await serve_timers()  # nothing to run: it returns at once
        return
    async with anyio.create_task_group() as tg:
        tg.start_soon(serve_timers)
        await anyio.wait_all_tasks_blocked()
        timers = current_timers()
        assert (timers.running, timers.participants) == (True, 1)
        start = anyio.current_time()
        await TrioWakeup().wait(0.05, coarse=True)
        assert anyio.current_time() - start >= 0.05
        assert timers.fired == 1
        tg.cancel_scope.cancel()
    assert (timers.running, timers.participants) == (False, 0)
