"""Trio's side of :mod:`._wakeup` (imported on trio only).

While a client runs the loop's shared timer (:mod:`._trio_timers`), a timed
wait goes on its heap: no cancel scope of its own. A coarse wait
(``coarse=True``) may end up to :data:`._trio_timers.GRID` late; either kind
may end early when the last client leaves the loop. A wait may name a
callback (``then``) that the loop runs when the deadline passes, before the
task would resume: it may keep the task waiting (the WebSocket reader's read
at the end of a wait, taken with no task step).

With nobody running the heap, a timed wait keeps a cancel scope (trio's only
timer is a scope's deadline), but when its own deadline is what interrupts
the wait the task resumes with a plain value: ``trio.sleep`` instead raises
``Cancelled`` through the waiting frames and catches it at the scope's exit
(an exception object, an outcome wrapping it, a traceback), and the
WebSocket reader's holds and a rate-capped consumer's waits end by their
deadline hundreds of times a second. A cancellation from outside still
raises ``Cancelled`` as usual; one that comes once the deadline has passed
is taken at the caller's next checkpoint.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

import trio
import trio.lowlevel

from ._trio_timers import GRID, Entry, TrioTimers, current_timers

__all__ = ["TrioWakeup"]

_log = logging.getLogger(__name__)

Then = Callable[[], "tuple[float, bool]"]
""":data:`._wakeup.Then` (spelled again: ``_wakeup`` imports this module)."""

_FAILED = trio.lowlevel.Abort.FAILED
_SUCCEEDED = trio.lowlevel.Abort.SUCCEEDED


class TrioWakeup:
    """:class:`._wakeup.Wakeup` on trio: the waiting task is parked and
    rescheduled directly."""

    __slots__ = ("_due", "_entry", "_exact", "_task", "_then", "_timers")

    def __init__(self) -> None:
        self._task: trio.lowlevel.Task | None = None
        self._timers: TrioTimers = current_timers()
        self._entry: Entry | None = None
        """This waiter's entry on the shared timer's heap, if one is there
        (it stays when a wait ends early, and serves the next wait whose
        deadline is not earlier)."""
        self._due = math.inf
        """The current wait's deadline on the heap (trio's clock)."""
        self._exact = False
        """The current wait on the heap is exact (not rounded to the grid)."""
        self._then: Then | None = None
        """The current wait's callback at its deadline, if any."""

    def set(self) -> None:
        task = self._task
        if task is not None:
            self._task = None
            trio.lowlevel.reschedule(task)

    def _abort(self, _raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
        self._task = None
        return _SUCCEEDED

    async def wait(
        self, timeout: float | None = None, *, coarse: bool = False, then: Then | None = None
    ) -> None:
        """Wait until :meth:`set` or ``timeout`` seconds (None: no limit).
        ``coarse``: may end up to :data:`._trio_timers.GRID` late. ``then``:
        while the loop's shared timer runs, called by the loop when the
        deadline passes, before the task would resume; it returns
        ``(seconds, coarse)``: a positive ``seconds`` keeps the task waiting
        that much longer (a :meth:`set` still ends the wait), 0 resumes it.
        It must not block; if it raises, the error is logged and the task
        resumes. Without a runner (or without a timeout) it is not called:
        the task resumes and the caller acts."""
        task = self._task = trio.lowlevel.current_task()
        if timeout is None:
            self._entry = None  # (a stale entry must not end this wait)
            await trio.lowlevel.wait_task_rescheduled(self._abort)
            return
        timers = self._timers
        if timers.running:
            self._then = then
            self._push(trio.current_time() + timeout, coarse)
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
    def _push(self, due: float, coarse: bool) -> None:
        """Have the heap end the current wait at ``due`` (rounded up to the
        grid when ``coarse``): an entry already there serves when it fires
        no later (then no earlier than ``due``, it pushes this wait's own)."""
        self._due = due
        self._exact = not coarse
        entry = self._entry
        if entry is None or entry[0] > (due + GRID if coarse else due):
            self._entry = self._timers.push(due, self, exact=not coarse)

    def owns(self, entry: Entry) -> bool:
        return entry is self._entry

    def expire(self, entry: Entry, now: float) -> None:
        if entry is not self._entry:
            return  # replaced by an earlier one
        self._entry = None
        if self._task is None:
            return  # the wait it was pushed for ended already
        due = self._due
        if due > now:  # an entry pushed for an earlier wait: push this wait's own
            self._entry = self._timers.push(due, self, exact=self._exact)
            return
        then = self._then
        if then is not None and now != math.inf:
            try:
                more, coarse = then()
            except Exception:  # (the loop's own code must not raise)
                _log.exception("a timed wait's callback failed; its task resumes")
                more = 0.0
            if more > 0.0 and self._task is not None:
                self._push(now + more, coarse)
                return
        self.set()
