"""One consumer task's wait for its producer, at the event loop's own cost.

A subscription's consumer waits once per delivery (thousands of times a
second across a fleet of connections). ``anyio.Event`` builds an event object
(on asyncio an ``asyncio.Event`` and its waiter list) per wait, and a timed
wait adds a cancel scope or a loop timer around it. :class:`Wakeup` is built
once per consumer and waits on what the loop itself offers: a future (and a
loop timer for a time limit) on asyncio; on trio the task is parked and
rescheduled directly, with an entry on the loop's shared timer as the time
limit (:mod:`._trio_timers`, run by :func:`serve_timers`) or, while nobody
runs that, a cancel scope's deadline (trio's only timer) that resumes the
task with a value instead of raising ``Cancelled`` through the waiting
frames.

Single waiter: one task waits at a time. :meth:`Wakeup.set` from the loop's
thread (a callback or another task) resumes it, or does nothing when nobody
waits. A cancellation from outside ends the wait as any checkpoint does.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from typing import Protocol

import sniffio

__all__ = ["Then", "Wakeup", "new_wakeup", "resolve", "serve_timers"]

Then = Callable[[], "tuple[float, bool]"]
"""A wait's callback at its deadline (see :meth:`Wakeup.wait`): how many
more seconds to wait and whether that wait is coarse, or ``(0.0, _)``."""


class Wakeup(Protocol):
    def set(self) -> None:
        """Resume the waiting task, if one waits; else nothing."""

    async def wait(
        self, timeout: float | None = None, *, coarse: bool = False, then: Then | None = None
    ) -> None:
        """Wait until :meth:`set`, or ``timeout`` seconds (None: no limit)
        pass; always suspends the task once (a checkpoint). ``coarse``: the
        wait may end up to a millisecond late, or early (trio: on the loop's
        shared timer, :mod:`._trio_timers`); the caller checks its condition
        again after any wake-up. ``then``: on trio, while the loop's shared
        timer runs, the loop calls it at the deadline instead of resuming
        the task; it returns ``(seconds, coarse)`` to go on waiting, or
        ``(0.0, _)`` to resume (see :meth:`._trio_wakeup.TrioWakeup.wait`).
        Elsewhere it is not called: the caller acts once resumed."""


def new_wakeup() -> Wakeup:
    """A :class:`Wakeup` for the running event loop (asyncio or trio)."""
    if sniffio.current_async_library() == "asyncio":
        return _AsyncioWakeup(asyncio.get_running_loop())
    from ._trio_wakeup import TrioWakeup  # (imports trio: installed, since it runs)

    return TrioWakeup()


async def serve_timers() -> None:
    """Take part in running the loop's shared timer of coarse waits until
    cancelled (each client runs this as one of its tasks). On asyncio there
    is none (a loop timer is cheap), and this returns at once."""
    if sniffio.current_async_library() == "asyncio":
        return
    from ._trio_timers import current_timers

    await current_timers().participate()


def resolve(future: asyncio.Future[None]) -> None:
    """Set ``future``'s result to None unless it is done (a loop timer's
    callback: the waiter may have been cancelled meanwhile)."""
    if not future.done():
        future.set_result(None)


class _AsyncioWakeup:
    __slots__ = ("_future", "_loop")

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._future: asyncio.Future[None] | None = None

    def set(self) -> None:
        future = self._future
        if future is not None:
            self._future = None
            if not future.done():
                future.set_result(None)

    async def wait(
        self, timeout: float | None = None, *, coarse: bool = False, then: Then | None = None
    ) -> None:
        loop = self._loop  # (a loop timer is cheap: every wait is exact)
        future = self._future = loop.create_future()
        timer = None if timeout is None else loop.call_later(timeout, resolve, future)
        try:
            await future
        finally:
            if timer is not None:
                timer.cancel()
            self._future = None
