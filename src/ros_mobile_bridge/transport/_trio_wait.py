"""A sleep for trio that ends without an exception (imported on trio only).

``trio.sleep`` is a cancel scope around a wait that never ends: the scope's
deadline cancels the wait, and the sleep ends by raising ``Cancelled`` through
the waiting frames and catching it at the scope's exit (an exception object,
an outcome wrapping it, a traceback). The WebSocket reader sleeps once per
read under read coalescing (hundreds of times a second under a steady
stream), so that is a share of every message's cost. :func:`sleep_until`
keeps the scope (trio's only timer is a scope's deadline) but, when its own
deadline is what interrupts the wait, resumes the task with a plain value
instead. A cancellation from outside still raises ``Cancelled`` as usual.
"""

from __future__ import annotations

import trio
import trio.lowlevel

__all__ = ["sleep", "sleep_until"]

_FAILED = trio.lowlevel.Abort.FAILED
_SUCCEEDED = trio.lowlevel.Abort.SUCCEEDED


async def sleep(seconds: float) -> None:
    """Sleep ``seconds``, as :func:`trio.sleep` does, and end without raising
    when the deadline ends the sleep. Cancelled from outside before the
    deadline, it raises ``Cancelled``; a cancellation from outside that comes
    once the deadline has passed is taken at the caller's next checkpoint."""
    task = trio.lowlevel.current_task()
    scope = trio.CancelScope(deadline=trio.current_time() + seconds)

    def abort(_raise_cancel: trio.lowlevel.RaiseCancelT) -> trio.lowlevel.Abort:
        if scope.cancel_called:  # the deadline passed: wake with a value
            trio.lowlevel.reschedule(task)
            return _FAILED
        return _SUCCEEDED  # cancelled from outside: Cancelled, as any sleep

    with scope:
        await trio.lowlevel.wait_task_rescheduled(abort)


async def sleep_until(deadline: float) -> None:
    """:func:`sleep` until ``deadline`` (:func:`trio.current_time`)."""
    await sleep(deadline - trio.current_time())
