"""When the WebSocket reader reads its socket: read coalescing and read holds.

A reader that reads as soon as anything arrives wakes once per frame. Two
waits before a read let frames gather in the kernel and be read, parsed and
handed over together:

* **Read coalescing** (``read_coalesce``): under a steady stream of small
  reads, the next read waits until the window after the last one ends. Each
  frame waits at most the window.
* **Read holds** (:meth:`ReadPacer.set_quiet`): while the owner says nobody
  can take a new message before a later time (every subscription is
  rate-capped and inside its window), the next read waits until then.

:class:`ReadPacer` holds the policy (when to wait, and how long) and does the
wait: on asyncio's :class:`~._asyncio_stream.ProtocolStream` the stream's
:meth:`~._asyncio_stream.ProtocolStream.hold` (reading paused, so nothing
wakes the loop meanwhile); elsewhere a :class:`.._loop._wakeup.Wakeup` (anyio's
streams read only when asked), which on trio may hand the end of the wait
to the owner's :attr:`ReadPacer.due` instead of resuming the reader. Used
by one :class:`~._websocket.WebSocket`; it never reads or parses itself.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Final

from .._loop._wakeup import Then, Wakeup, new_wakeup
from ._asyncio_stream import ProtocolStream

__all__ = ["COALESCE_BELOW", "HOLD_DRAIN", "ReadPacer"]

COALESCE_BELOW: Final = 64 * 1024
"""A read of this many bytes or more ends read coalescing until the next
small read, and prevents a hold before the next read: the stream is
saturated, and waiting could only slow it."""
_HOLD_MIN: Final = 0.005
"""Seconds below which a hold is not made (a hold costs a timer: shorter
ones save nothing)."""
HOLD_DRAIN: Final = 1024 * 1024
"""Bytes the reads right after a hold take at most: what waited is handed
over together."""
_HOLD_MAX: Final = 1.0
"""Seconds one hold lasts at most: longer quiet windows are held in parts,
so a close or a graph change waits at most this long to be read."""


class ReadPacer:
    """The waits of one WebSocket reader before its reads (see the module
    docstring). ``stream``: asyncio's protocol stream under the WebSocket,
    else None."""

    __slots__ = (
        "_stream",
        "_wakeup",
        "coalesced",
        "drain",
        "due",
        "last_read",
        "quiet",
        "quiet_holds",
        "saturated",
        "steady",
        "window",
    )

    def __init__(self, stream: ProtocolStream | None) -> None:
        self._stream = stream
        self._wakeup: Wakeup | None = None  # built by the reader, on its loop
        self.window = 0.0
        """``read_coalesce``: seconds a read may wait under a steady stream
        of small reads (0: never)."""
        self.quiet: Callable[[float], float] | None = None
        """:meth:`set_quiet`'s callable, or None."""
        self.steady = False
        """Read coalescing is on for the next read."""
        self.last_read = 0.0
        """``time.monotonic()`` when the last read returned."""
        self.saturated = False
        """The last read brought :data:`COALESCE_BELOW` bytes or more."""
        self.drain = False
        """The last wait was a hold: the read after it takes all that
        waited, up to :data:`HOLD_DRAIN` bytes."""
        self.quiet_holds = 0
        """Waits made for :meth:`set_quiet` (the subscriptions' caps)."""
        self.coalesced = 0
        """Waits made for read coalescing."""
        self.due: Then | None = None
        """On trio (the loop's shared timer running): called by the loop at
        the end of a wait instead of resuming the reader (the owner's read
        there, see :meth:`.._loop._trio_wakeup.TrioWakeup.wait`); returns how long
        to go on waiting and whether that is a hold, or ``(0.0, False)``:
        the reader resumes and reads."""

    @property
    def active(self) -> bool:
        """The next read may wait (:meth:`wait` has something to decide)."""
        return self.steady or self.quiet is not None

    def inline_time(self, nbytes: int, pongs: bool) -> float | None:
        """For a read of ``nbytes`` the loop made on its own (asyncio's read
        callback): None when the reader must take it instead (reads come
        faster than the window, so the reader coalesces them; or a hold is
        due and the read is small), else the time to record with
        :meth:`read_taken` once the read was taken whole. ``pongs``: a ping
        waits for its pong (then nothing is held)."""
        window = self.window
        quiet = self.quiet
        if not window and quiet is None:
            return 0.0
        now = time.monotonic()
        if window and now - self.last_read < window:
            return None
        if (
            quiet is not None
            and nbytes < COALESCE_BELOW
            and quiet(now) - now >= _HOLD_MIN
            and not pongs
        ):
            return None
        return now

    def read_taken(self, now: float) -> None:
        """A read was taken whole where it was read, at ``now`` (from
        :meth:`inline_time`)."""
        self.last_read = now

    def after_read(self, nbytes: int, waited: bool, messages: int) -> None:
        """The reader read ``nbytes``, after a wait of :meth:`wait` when
        ``waited``, bringing ``messages`` messages: coalescing starts when
        reads come faster than the window and stops when a read that waited
        brought one message or none (the stream is too slow to gather
        several) or a read is :data:`COALESCE_BELOW` bytes or more."""
        self.saturated = saturated = nbytes >= COALESCE_BELOW
        window = self.window
        if window:
            now = time.monotonic()
            if saturated:
                self.steady = False
            elif waited:  # keep waiting while it gathers more than one message
                self.steady = messages > 1
            else:
                self.steady = now - self.last_read < window
            self.last_read = now

    async def wait(self, pongs: bool) -> bool:
        """Wait before the next read, if the policy says so; True when it
        waited.

        Under a steady stream, until :attr:`window` seconds after the last
        read returned (not at all when handling that read took longer).
        Longer while :attr:`quiet` says nobody can take a frame before a
        later time (at most :data:`_HOLD_MAX` per wait; not while a ping
        waits for its pong (``pongs``), nor after a saturated read: more
        waits, and holding would slow the server). Ended early by
        :meth:`end`."""
        delay, holding = self.delay(pongs)
        if delay <= 0:
            return False
        stream = self._stream
        if stream is not None and stream.has_data:
            return False  # bytes that arrived before the wait are read at once
        self.waited(holding)  # (counted first: a hold continued by its stream counts its own)
        if stream is not None:
            # reading paused: no wake-up per arriving segment
            await stream.hold(delay, drain=holding)
        else:
            wakeup = self._wakeup
            if wakeup is None:
                wakeup = self._wakeup = new_wakeup()
            # (on trio no Cancelled raised and caught; a hold may end a
            # millisecond late, on the loop's shared timer, and the read at
            # the end of the wait may be made there, by self.due)
            await wakeup.wait(delay, coarse=holding, then=self.due)
        return True

    def delay(self, pongs: bool) -> tuple[float, bool]:
        """How long :meth:`wait` would wait now, and whether that is a hold."""
        now = time.monotonic()
        delay = self.last_read + self.window - now if self.steady else 0.0
        quiet = self.quiet
        holding = False
        if quiet is not None and not pongs and not self.saturated:
            wait = quiet(now) - now
            if wait > delay and wait >= _HOLD_MIN:
                delay = wait if wait < _HOLD_MAX else _HOLD_MAX
                holding = True
        return delay, holding

    def waited(self, holding: bool) -> None:
        """Count one wait (:meth:`wait`'s, or one its stream continued) and
        note its kind for the read after it."""
        self.drain = holding
        if holding:
            self.quiet_holds += 1
        else:
            self.coalesced += 1

    def set_quiet(self, quiet: Callable[[float], float] | None) -> None:
        """Hold reads while ``quiet(now)`` (monotonic seconds) returns a
        time :data:`_HOLD_MIN` or more ahead: the time before which no
        reader of the connection can take a new message (0.0: none). None
        stops, and ends a wait."""
        self.quiet = quiet
        if quiet is None:
            self.end()

    def end(self) -> None:
        """End the current :meth:`wait`, if one waits: the reader reads now."""
        stream = self._stream
        if stream is not None:
            stream.end_hold()
        elif self._wakeup is not None:
            self._wakeup.set()
