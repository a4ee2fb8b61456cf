"""One timer for a trio loop's timed waits (imported on trio only).

trio's only timer is a cancel scope's deadline: entering the scope, trio
expiring it and leaving it cost about 15-20 us of CPU per timed wait (a
plain park and resume costs about 2 us). A fleet of rate-capped connections
waits thousands of times a second: each WebSocket reader holds its reads
until its subscriptions' next window (:mod:`..transport._read_pacing`), and
each consumer waits for the end of its cap's window (:mod:`..flow._subscription`);
a single fast stream's reader waits once per read for read coalescing.

While a client runs it, a timed wait (:meth:`._trio_wakeup.TrioWakeup.wait`)
pushes its deadline on one heap per loop and parks. One task per loop, the
:class:`TrioTimers` runner, holds one cancel scope for its whole life, whose
deadline is the heap's earliest, so that the loop's wait for I/O ends then.
Right after that wait (a trio instrument, ``after_io_wait``), the loop itself
resumes every waiter whose deadline passed and moves the scope's deadline to
the next one, before trio would expire it: a wait costs a heap push and a
park, and the waiters resume in the same batch of tasks that trio's own
deadline would have resumed them in. A waiter may instead be handed a
callback to run there (:meth:`Expiring.expire`; the WebSocket reader's read
at the end of a wait, taken with no task step).

A *coarse* wait's deadline is rounded up to :data:`GRID`, so that waits
ending within the same millisecond end in one wake-up (a fleet's holds); an
exact one is not rounded.

Ownership: every client on the loop runs :meth:`TrioTimers.participate` as one of its
tasks (:class:`._relay.Relay`): one runs the heap, the others wait to take
over. While nobody runs it, timed waits use their own cancel scope; when
the last participant leaves, every waiter still on the heap is resumed (a
wait on the heap may then end early: its caller checks its condition again,
as after any wake-up).
"""

from __future__ import annotations

import contextlib
import heapq
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, Final, NoReturn, Protocol

import trio
import trio.lowlevel
from anyio.lowlevel import RunVar

from ._relay import Relay

if TYPE_CHECKING:
    from typing import TypeAlias

__all__ = ["COMPACT_ABOVE", "GRID", "TrioTimers", "current_timers"]

GRID: Final = 0.001
"""Seconds: a coarse wait's deadline is rounded up to a multiple of this, so
coarse waits that end within the same millisecond end in one wake-up."""
COMPACT_ABOVE: Final = 4096
"""Entries on the heap at which a push first rebuilds it without the entries
whose waiter has since pushed another (an entry is left on the heap when its
wait ends early; it is dropped when its deadline passes, or here). The next
rebuild comes at twice what was kept, and never below this."""


class Expiring(Protocol):
    """A waiter on the heap (a :class:`._trio_wakeup.TrioWakeup`)."""

    def expire(self, entry: Entry, now: float) -> None:
        """``entry``'s deadline passed (``now``: trio's clock). Called by the
        loop between its wait for I/O and its next batch of tasks (or with
        an infinite ``now`` when the last participant leaves): it must not
        block and must not raise."""

    def owns(self, entry: Entry) -> bool:
        """``entry`` is the waiter's current one (not replaced since)."""


Entry: TypeAlias = "tuple[float, int, Expiring]"
"""(deadline on trio's clock, push order, waiter)."""


class TrioTimers:
    """The heap of one trio loop's coarse waits and its runner (see the
    module docstring)."""

    __slots__ = ("_compact_at", "_heap", "_relay", "_scope", "_seq", "fired", "rearmed", "wakeups")

    def __init__(self) -> None:
        self._heap: list[Entry] = []
        self._seq = 0
        self._compact_at = COMPACT_ABOVE
        self._scope: trio.CancelScope | None = None  # the runner's, while it runs
        self._relay = Relay()
        self.fired = 0
        """Entries whose deadline passed while on the heap."""
        self.wakeups = 0
        """Times the loop resumed waiters from the heap (each ends every wait
        due by then)."""
        self.rearmed = 0
        """Times trio expired the runner's scope before it was moved on (its
        deadline passed between the instrument's clock reading and trio's):
        the runner then starts a new scope."""

    @property
    def running(self) -> bool:
        """A participant runs the heap: a coarse wait may use it."""
        return self._relay.running

    @property
    def participants(self) -> int:
        """How many :meth:`participate` calls are running (one per client on
        the loop)."""
        return self._relay.participants

    def __len__(self) -> int:
        return len(self._heap)

    def push(self, deadline: float, waiter: Expiring, *, exact: bool = False) -> Entry:
        """Call ``waiter.expire(entry, now)`` once trio's clock passes
        ``deadline``, rounded up to :data:`GRID` unless ``exact``; returns
        the entry."""
        heap = self._heap
        if len(heap) >= self._compact_at:
            heap = self._compact()
        if not exact:
            deadline = math.ceil(deadline / GRID) * GRID
        self._seq += 1
        entry = (deadline, self._seq, waiter)
        heapq.heappush(heap, entry)
        scope = self._scope
        if scope is not None and deadline < scope.deadline:
            scope.deadline = deadline  # (moves the runner's wake-up forward)
        return entry

    def _compact(self) -> list[Entry]:
        """Drop the entries their waiter replaced since (before a push: the
        entry being pushed is not its waiter's yet)."""
        heap = [entry for entry in self._heap if entry[2].owns(entry)]
        heapq.heapify(heap)
        self._heap = heap
        self._compact_at = max(COMPACT_ABOVE, 2 * len(heap))  # (amortised: O(log n) a push)
        return heap

    def expire_due(self, now: float) -> None:
        """Resume the waiters whose deadline is ``now`` (trio's clock) or
        earlier, then move the runner's scope to the next deadline."""
        heap = self._heap
        if heap and heap[0][0] <= now:
            self.wakeups += 1
            while heap and heap[0][0] <= now:
                entry = heapq.heappop(heap)
                self.fired += 1
                entry[2].expire(entry, now)
            heap = self._heap  # (a push may have rebuilt it)
        scope = self._scope
        if scope is not None:
            deadline = heap[0][0] if heap else math.inf
            if scope.deadline != deadline:
                scope.deadline = deadline

    async def run(self) -> NoReturn:
        """The runner, until cancelled (driven by :meth:`participate`): one
        cancel scope whose deadline is the earliest on the heap, so that the
        loop wakes then. The loop itself resumes the waiters due, right
        after its wait for I/O (:class:`_AfterIoWait`), and moves the
        scope's deadline on before trio expires it: in the same batch of
        tasks as trio's own deadlines would resume them, with no scope
        entered or expired per wait. Should trio expire the scope anyway
        (its deadline passed after the instrument read the clock), the
        runner resumes the waiters due itself and starts a new scope."""
        task = trio.lowlevel.current_task()
        instrument = _AfterIoWait(self)
        trio.lowlevel.add_instrument(instrument)
        try:
            while True:
                heap = self._heap
                scope = self._scope = trio.CancelScope(deadline=heap[0][0] if heap else math.inf)
                with scope:
                    await trio.lowlevel.wait_task_rescheduled(_waker(task, scope))
                self._scope = None
                self.rearmed += 1
                self.expire_due(trio.current_time())
        finally:
            self._scope = None
            with contextlib.suppress(KeyError):  # (trio drops an instrument that raised)
                trio.lowlevel.remove_instrument(instrument)

    async def participate(self) -> NoReturn:
        """Take part in running this heap until cancelled (see the module
        docstring)."""
        await self._relay.participate(self.run, self.release_all)

    def release_all(self) -> None:
        """Resume every waiter on the heap now (nobody runs it any more)."""
        heap, self._heap = self._heap, []
        for entry in heap:
            entry[2].expire(entry, math.inf)


class _AfterIoWait(trio.abc.Instrument):
    """Resumes the heap's due waiters after each of the loop's waits for
    I/O, while the heap has a runner."""

    __slots__ = ("_timers",)

    def __init__(self, timers: TrioTimers) -> None:
        self._timers = timers

    def after_io_wait(self, timeout: float) -> None:
        self._timers.expire_due(trio.current_time())


def _waker(
    task: trio.lowlevel.Task, scope: trio.CancelScope
) -> Callable[[trio.lowlevel.RaiseCancelT], trio.lowlevel.Abort]:
    """The abort function of the runner's sleep: its deadline passing wakes
    it with a value (no ``Cancelled`` raised and caught); a cancellation
    from outside raises as usual."""

    def abort(_raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
        if scope.cancel_called:
            trio.lowlevel.reschedule(task)
            return trio.lowlevel.Abort.FAILED
        return trio.lowlevel.Abort.SUCCEEDED

    return abort


_TIMERS: RunVar[TrioTimers] = RunVar("ros_mobile_bridge.trio_timers")


def current_timers() -> TrioTimers:
    """The running trio loop's :class:`TrioTimers`, created on first use."""
    try:
        return _TIMERS.get()
    except LookupError:
        timers = TrioTimers()
        _TIMERS.set(timers)
        return timers
