"""Trio's side of :mod:`._wakeup` (imported on trio only).

A timed wait keeps a cancel scope (trio's only timer is a scope's deadline),
but when its own deadline is what interrupts the wait the task resumes with a
plain value: ``trio.sleep`` instead raises ``Cancelled`` through the waiting
frames and catches it at the scope's exit (an exception object, an outcome
wrapping it, a traceback), and the WebSocket reader's holds and a rate-capped
consumer's waits end by their deadline hundreds of times a second. A
cancellation from outside still raises ``Cancelled`` as usual; one that comes
once the deadline has passed is taken at the caller's next checkpoint.

A coarse wait (``coarse=True``) goes on the loop's shared timer instead
(:mod:`._trio_timers`) while a client runs it: no cancel scope of its own,
and it may end up to :data:`._trio_timers.GRID` late (or early, when the
last client leaves the loop).
"""

from __future__ import annotations

import math

import trio
import trio.lowlevel

from ._trio_timers import GRID, Entry, TrioTimers, current_timers

__all__ = ["TrioWakeup"]

_FAILED = trio.lowlevel.Abort.FAILED
_SUCCEEDED = trio.lowlevel.Abort.SUCCEEDED


class TrioWakeup:
    """:class:`._wakeup.Wakeup` on trio: the waiting task is parked and
    rescheduled directly."""

    __slots__ = ("_due", "_entry", "_task", "_timers")

    def __init__(self) -> None:
        self._task: trio.lowlevel.Task | None = None
        self._timers: TrioTimers = current_timers()
        self._entry: Entry | None = None
        """This waiter's entry on the shared timer's heap, if one is there
        (it stays when a wait ends early, and serves the next wait whose
        deadline is not earlier)."""
        self._due = math.inf
        """The current coarse wait's deadline (trio's clock)."""

    def set(self) -> None:
        task = self._task
        if task is not None:
            self._task = None
            trio.lowlevel.reschedule(task)

    def _abort(self, _raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
        self._task = None
        return _SUCCEEDED

    async def wait(self, timeout: float | None = None, *, coarse: bool = False) -> None:
        task = self._task = trio.lowlevel.current_task()
        if timeout is None:
            self._entry = None  # (a stale entry must not end this wait)
            await trio.lowlevel.wait_task_rescheduled(self._abort)
            return
        if coarse and self._timers.running:
            self._due = due = trio.current_time() + timeout
            entry = self._entry
            if entry is None or entry[0] > due + GRID:  # (else it ends this wait in time)
                self._entry = self._timers.push(due, self)
            await trio.lowlevel.wait_task_rescheduled(self._abort)
            return
        self._entry = None
        scope = trio.CancelScope(deadline=trio.current_time() + timeout)

        def abort_timed(_raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
            self._task = None
            if scope.cancel_called:  # the deadline passed: wake with a value
                trio.lowlevel.reschedule(task)
                return _FAILED
            return _SUCCEEDED  # cancelled from outside: Cancelled, as any wait

        with scope:
            await trio.lowlevel.wait_task_rescheduled(abort_timed)

    # -- the shared timer's side ----------------------------------------------------
    def owns(self, entry: Entry) -> bool:
        return entry is self._entry

    def expire(self, entry: Entry, now: float) -> None:
        if entry is not self._entry:
            return  # replaced by an earlier one
        self._entry = None
        if self._task is None:
            return  # the wait it was pushed for ended already
        due = self._due
        if due <= now:  # (release_all passes an infinite now)
            self.set()
        else:  # an entry pushed for an earlier wait: push this wait's own
            self._entry = self._timers.push(due, self)
