"""One worker per event loop, run by whichever of its users is still there.

Some work serves every client on a loop at once: the lag sampler
(:mod:`..flow._lag`) and, on trio, the shared timer of coarse waits
(:mod:`._trio_timers`). No client may own it alone (it would stop when that
client closes), and a task outside every task group would outlive them all.
So each client runs :meth:`Relay.participate` as one of its own tasks: the
first participant runs the work, the others wait; when the running one is
cancelled (its client closed) a waiting one takes over at once, and when the
last leaves the work stops.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import NoReturn

import anyio

__all__ = ["Relay"]


class Relay:
    """Who runs one loop's shared work (see the module docstring). Built in
    async code on the loop it serves (it holds an ``anyio.Event``)."""

    __slots__ = ("_handover", "_participants", "_running")

    def __init__(self) -> None:
        self._participants = 0
        self._running = False
        self._handover = anyio.Event()

    @property
    def participants(self) -> int:
        """How many :meth:`participate` calls are running."""
        return self._participants

    @property
    def running(self) -> bool:
        """Whether a participant runs the work now."""
        return self._running

    async def participate(
        self,
        work: Callable[[], Awaitable[NoReturn]],
        last_left: Callable[[], object] | None = None,
    ) -> NoReturn:
        """Take part until cancelled: run ``work()`` when no other
        participant does, else wait to take over. ``last_left()`` is called
        (synchronously, in the cancelled task) when the last participant
        leaves: nobody runs the work any more."""
        self._participants += 1
        try:
            while True:
                if self._running:
                    await self._handover.wait()
                    continue
                self._running = True
                try:
                    await work()
                finally:
                    self._running = False
                    handover, self._handover = self._handover, anyio.Event()
                    handover.set()
        finally:
            self._participants -= 1
            if not self._participants and last_left is not None:
                last_left()
