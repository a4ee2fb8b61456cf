"""Trio's side of :mod:`._wakeup` (imported on trio only).

A timed wait keeps a cancel scope (trio's only timer is a scope's deadline),
but when its own deadline is what interrupts the wait the task resumes with a
plain value: ``trio.sleep`` instead raises ``Cancelled`` through the waiting
frames and catches it at the scope's exit (an exception object, an outcome
wrapping it, a traceback), and the WebSocket reader's holds and a rate-capped
consumer's waits end by their deadline hundreds of times a second. A
cancellation from outside still raises ``Cancelled`` as usual; one that comes
once the deadline has passed is taken at the caller's next checkpoint.
"""

from __future__ import annotations

import trio
import trio.lowlevel

__all__ = ["TrioWakeup"]

_FAILED = trio.lowlevel.Abort.FAILED
_SUCCEEDED = trio.lowlevel.Abort.SUCCEEDED


class TrioWakeup:
    """:class:`._wakeup.Wakeup` on trio: the waiting task is parked and
    rescheduled directly."""

    __slots__ = ("_task",)

    def __init__(self) -> None:
        self._task: trio.lowlevel.Task | None = None

    def set(self) -> None:
        task = self._task
        if task is not None:
            self._task = None
            trio.lowlevel.reschedule(task)

    async def wait(self, timeout: float | None = None) -> None:
        task = self._task = trio.lowlevel.current_task()
        if timeout is None:

            def abort(_raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
                self._task = None
                return _SUCCEEDED

            await trio.lowlevel.wait_task_rescheduled(abort)
            return
        scope = trio.CancelScope(deadline=trio.current_time() + timeout)

        def abort_timed(_raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
            self._task = None
            if scope.cancel_called:  # the deadline passed: wake with a value
                trio.lowlevel.reschedule(task)
                return _FAILED
            return _SUCCEEDED  # cancelled from outside: Cancelled, as any wait

        with scope:
            await trio.lowlevel.wait_task_rescheduled(abort_timed)
