"""A TCP byte stream for asyncio built on ``asyncio.Protocol``.

anyio's ``SocketStream`` on asyncio resumes and pauses the transport's
reading around every ``receive()``: two epoll registrations per read, and a
checkpoint. For a client that wakes once per small frame on many connections
that bookkeeping costs more than the read itself. This stream keeps the
socket registered while data flows: ``data_received`` appends to a buffer and
wakes the reader, and reading is paused only when the buffer holds more than
:data:`_HIGH_WATER` bytes the reader has not taken (back-pressure on the
peer, as anyio's stream does).

It implements the part of ``anyio.abc.ByteStream`` the WebSocket uses
(``receive``, ``send``, ``send_eof``, ``aclose``) with anyio's exceptions:
``EndOfStream`` after the peer's EOF, ``BrokenResourceError`` once the
connection failed, ``ClosedResourceError`` after :meth:`aclose`. ``receive``
does not checkpoint when data is already buffered: the WebSocket's reader
yields to the loop on its own schedule. Used for plain TCP on asyncio only;
TLS and trio keep anyio's streams. It runs on uvloop as on asyncio's own
loop (uvloop's transports have ``asyncio.Transport``'s methods without
deriving from it, so nothing here checks the class).

A large frame's bytes can go straight where they belong:
:meth:`ProtocolStream.receive_into` has the next read of the socket land in
the caller's buffer (an ``asyncio.BufferedProtocol`` read), with no
intermediate ``bytes``; other reads land in one buffer per thread and are
copied out at their exact size.

Bytes can also be handled where they are read: :attr:`ProtocolStream.inline`,
a synchronous callable the owner installs, gets each read made while the
reader waits with nothing buffered, and says how many of its bytes it took;
the rest is buffered and wakes the reader as usual. A read taken whole costs
no task step (the WebSocket's fast path uses it for whole data frames). The
same goes for the read at the end of a :meth:`ProtocolStream.hold` (a wait
with reading paused): :attr:`ProtocolStream.paced` takes it in the timer's
callback and may continue the hold from there.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import sys
import threading
from collections import deque
from collections.abc import Callable
from typing import Final, cast

import anyio
import anyio.abc

from .._loop._wakeup import resolve

__all__ = ["ProtocolStream", "connect_tcp"]

_HIGH_WATER: Final = 4 * 1024 * 1024
"""Unread bytes at which reading from the socket pauses."""
_LOW_WATER: Final = 1024 * 1024
"""Unread bytes below which it resumes."""
_HOLD_READ: Final = 64 * 1024
"""Bytes one :meth:`ProtocolStream.hold` reads from the socket at most
(the read coalescing's size; a larger buffer is a fresh mapping of memory,
three more system calls, per read)."""


_HOLD_DRAIN: Final = 1024 * 1024
"""Bytes the reads after one :meth:`ProtocolStream.hold` take at most."""
_READ_SIZE: Final = 256 * 1024
"""Bytes one read of the socket takes at most (asyncio's own read size)."""

_scratch = threading.local()


def _read_buffer() -> memoryview:
    """This thread's read buffer (:data:`_READ_SIZE` bytes): the event loop
    reads into it and :meth:`_Protocol.buffer_updated` copies the bytes out
    at once, so every connection of the thread's loop shares it."""
    try:
        buf: memoryview = _scratch.buf
    except AttributeError:
        buf = _scratch.buf = memoryview(bytearray(_READ_SIZE))
    return buf


class _Protocol(asyncio.BufferedProtocol):
    """The asyncio side of one :class:`ProtocolStream`: what the event loop
    calls fills the buffer and wakes the waiting reader or writers. Its
    attributes and :meth:`wake_reader`/:meth:`wake_drainers` are internal,
    for ProtocolStream (which reads and sets them directly: no call layer
    per read)."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self.loop = loop
        self.transport: asyncio.Transport | None = None
        self.chunks: deque[bytes] = deque()
        self.buffered = 0
        self.read_paused = False
        self.held = False  # read_paused by ProtocolStream.hold, not by back-pressure
        self.hold_waiter: asyncio.Future[None] | None = None  # a hold's, while it waits
        self.eof = False
        self.error: BaseException | None = None
        self.reader: asyncio.Future[None] | None = None
        self.write_paused = False
        self.drainers: list[asyncio.Future[None]] = []
        self.inline: Callable[[bytes], int] | None = None
        # ProtocolStream.receive_into: where the next read lands, and how
        # many bytes it brought (until receive_into takes the count)
        self.target: memoryview | None = None
        self.target_filled = 0

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        # not an isinstance check: uvloop's TCP transport has asyncio.Transport's
        # methods without deriving from it
        self.transport = cast("asyncio.Transport", transport)

    def get_buffer(self, sizehint: int) -> memoryview:
        target = self.target
        return target if target is not None else _read_buffer()

    def buffer_updated(self, nbytes: int) -> None:
        if self.target is not None:  # the read landed in receive_into's buffer
            self.target = None
            self.target_filled = nbytes
            self.wake_reader()
        else:
            self.data_received(bytes(_read_buffer()[:nbytes]))

    def data_received(self, data: bytes) -> None:
        inline = self.inline
        if inline is not None and self.reader is not None and not self.chunks:
            # the reader waits with nothing buffered: the owner may take the
            # bytes here, in this callback, without a task step
            taken = inline(data)
            if taken:
                if taken >= len(data):
                    return
                data = data[taken:]
        self.chunks.append(data)
        self.buffered += len(data)
        if self.buffered > _HIGH_WATER and not self.read_paused and self.transport is not None:
            self.read_paused = True
            self.transport.pause_reading()
        self.wake_reader()

    def eof_received(self) -> bool:
        self.eof = True
        self.wake_reader()
        return True  # half-closed, as a socket: our close reply may still go out

    def connection_lost(self, exc: Exception | None) -> None:
        self.eof = True
        if exc is not None and self.error is None:
            self.error = exc
        self.wake_reader()
        self.write_paused = False
        self.wake_drainers()

    def pause_writing(self) -> None:
        self.write_paused = True

    def resume_writing(self) -> None:
        self.write_paused = False
        self.wake_drainers()

    def wake_reader(self) -> None:
        """Resume the task waiting in :meth:`ProtocolStream.receive`, if any."""
        reader = self.reader
        if reader is not None:
            self.reader = None
            if not reader.done():
                reader.set_result(None)

    def wake_drainers(self) -> None:
        """Resume the tasks waiting in :meth:`ProtocolStream.send` for the
        socket's buffer to drain."""
        drainers, self.drainers = self.drainers, []
        for fut in drainers:
            if not fut.done():
                fut.set_result(None)


class ProtocolStream(anyio.abc.ByteStream):
    """One connected TCP socket (see the module docstring). Single reader:
    two tasks must not wait in :meth:`receive` at once."""

    def __init__(self, transport: asyncio.Transport, protocol: _Protocol) -> None:
        self._transport = transport
        self._protocol = protocol
        self._closed = False
        self.held_reads = 0
        """Reads :meth:`hold` made itself, with the transport's reading paused."""
        sock = transport.get_extra_info("socket")
        # hold reads the paused socket itself where a socket is a file (not Windows)
        self._fd: int = sock.fileno() if sock is not None and sys.platform != "win32" else -1
        self.paced: Callable[[bytes], tuple[int, float]] | None = None
        """Called with the read a :meth:`hold`'s timer makes, in the timer's
        callback (so it must not block, and must not raise); returns how
        many leading bytes it took (handled for good) and, when it took
        them all, how many seconds the hold goes on before the next read
        (0.0: the hold ends). The rest is buffered and the hold ends. None
        (the default): the hold ends at its timer and the waiting task
        reads."""
        self.paced_reads = 0
        """Reads a hold's timer made and :attr:`paced` took whole: each one
        a wake-up of the loop with no task step."""
        self._hold_timer: asyncio.TimerHandle | None = None
        self._hold_read = False  # the hold's timer read all the socket held (_hold_due)

    async def receive(self, max_bytes: int = 65536) -> bytes:
        p = self._protocol
        while not p.chunks:
            self._ready_to_wait()
            p.reader = waiter = p.loop.create_future()
            try:
                await waiter
            finally:
                if p.reader is waiter:
                    p.reader = None
        data = p.chunks.popleft()  # one chunk as the socket gave it: no joining copy
        if len(data) > max_bytes:
            p.chunks.appendleft(data[max_bytes:])
            data = data[:max_bytes]
        p.buffered -= len(data)
        self._resume_below_low_water()
        return data

    async def receive_into(self, view: memoryview) -> int:
        """Read up to ``len(view)`` bytes (at least one) into ``view``; returns
        how many. Bytes already buffered are copied in first; otherwise the
        next read of the socket lands in ``view`` itself. Same exceptions as
        :meth:`receive`. A call cancelled after its read landed returns that
        read's count from the next call, which must then pass a view
        starting at the same place."""
        p = self._protocol
        while True:
            n = p.target_filled
            if n:  # (before the buffer: later reads may have been buffered)
                p.target_filled = 0
                return n
            if p.chunks:
                break
            self._ready_to_wait()
            p.target = view
            p.reader = waiter = p.loop.create_future()
            try:
                await waiter
            finally:
                p.target = None
                if p.reader is waiter:
                    p.reader = None
        data = p.chunks.popleft()
        n = len(data)
        if n > len(view):
            p.chunks.appendleft(data[len(view) :])
            n = len(view)
            view[:] = memoryview(data)[:n]
        else:
            view[:n] = data
        p.buffered -= n
        self._resume_below_low_water()
        return n

    def _ready_to_wait(self) -> None:
        """Before a read waits for the socket: raise what the stream's state
        says (closed, ended, failed, another reader), and end a hold."""
        p = self._protocol
        if self._closed:
            raise anyio.ClosedResourceError
        if p.eof:
            if p.error is not None:
                raise anyio.BrokenResourceError from p.error
            raise anyio.EndOfStream
        if p.reader is not None:
            raise RuntimeError("another task is already reading from this stream")
        if p.held:
            self._resume_held()

    def _resume_below_low_water(self) -> None:
        p = self._protocol
        if (
            p.read_paused
            and not p.held
            and p.buffered < _LOW_WATER
            and not self._transport.is_closing()
        ):
            p.read_paused = False
            self._transport.resume_reading()

    @property
    def inline(self) -> Callable[[bytes], int] | None:
        """Called with each read made while a task waits in :meth:`receive`
        and nothing is buffered, in the event loop's read callback (so it
        must not block, and must not raise); returns how many leading bytes
        it took (handled for good). The rest is buffered for :meth:`receive`.
        None (the default): every read is buffered."""
        return self._protocol.inline

    @inline.setter
    def inline(self, handler: Callable[[bytes], int] | None) -> None:
        self._protocol.inline = handler

    @property
    def has_data(self) -> bool:
        """Bytes are buffered: :meth:`receive` returns without waiting."""
        return bool(self._protocol.chunks)

    async def hold(self, seconds: float, *, drain: bool = False) -> None:
        """Leave the socket unread for ``seconds``: reading is paused, so what
        arrives meanwhile waits in the kernel and is then read in one go
        (one wake-up of the loop instead of one per arriving segment).

        After the wait, the stream reads the paused socket itself (one
        non-blocking read of up to :data:`_HOLD_READ` bytes) and, when that
        brought bytes, leaves reading paused for the next hold: under a
        steady stream each hold is then one timer and one read, without
        pausing, resuming and waiting for the loop to report the socket
        readable. :meth:`receive` resumes reading whenever it has to wait.
        When the read finds nothing, the end of the stream or an error,
        reading resumes and the transport sees the same. Not on Windows
        (reading resumes after the wait). Cancellable; reading resumes on a
        cancelled hold. ``drain``: read the socket again while each read
        fills its buffer, up to :data:`_HOLD_DRAIN` bytes (what waited is
        handed over together; not for a stream of large frames, which are
        read straight into their buffers).

        With :attr:`paced` set, the timer's callback reads the socket and
        offers the read to it: while it takes each read whole and asks for
        another wait, the hold goes on from the callback, and the waiting
        task is not resumed at all (under a steady stream the waits of read
        coalescing cost a timer and a read each, with no task step)."""
        p = self._protocol
        if not p.read_paused and not self._transport.is_closing():
            p.read_paused = p.held = True
            self._transport.pause_reading()
        waiter = p.hold_waiter = p.loop.create_future()  # (asyncio.sleep without its loop lookup)
        self._hold_read = False
        self._hold_timer = p.loop.call_later(seconds, self._hold_due, waiter)
        try:
            await waiter
        except BaseException:
            self._hold_timer.cancel()
            if p.held:
                self._resume_held()
            raise
        finally:
            p.hold_waiter = None
        self._hold_timer.cancel()  # (ended early by end_hold)
        if p.held and not self._hold_read:
            self._read_held(_HOLD_DRAIN if drain else _HOLD_READ)

    def _hold_due(self, waiter: asyncio.Future[None]) -> None:
        """A :meth:`hold`'s timer: end the hold, or (see :attr:`paced`) read
        the paused socket here and go on holding while the read is taken."""
        if waiter.done():  # (ended by end_hold, or cancelled)
            return
        p = self._protocol
        paced = self.paced
        if paced is None or not p.held or p.chunks or self._fd < 0 or p.eof:
            resolve(waiter)
            return
        try:
            data = os.read(self._fd, _HOLD_READ)
        except OSError:  # nothing yet, or an error: the hold's own read meets it
            resolve(waiter)
            return
        if not data:  # the end of the stream: likewise
            resolve(waiter)
            return
        self._hold_read = len(data) < _HOLD_READ  # else more may wait: the hold reads on
        self.held_reads += 1
        taken, delay = paced(data)
        if taken < len(data):
            rest = data[taken:] if taken else data
            p.chunks.append(rest)
            p.buffered += len(rest)
            resolve(waiter)
            return
        self.paced_reads += 1
        if delay > 0:
            self._hold_timer = p.loop.call_later(delay, self._hold_due, waiter)
        else:
            resolve(waiter)

    def end_hold(self) -> None:
        """End the current :meth:`hold` now, if one waits (it then reads as
        at its end)."""
        waiter = self._protocol.hold_waiter
        if waiter is not None:
            resolve(waiter)

    def _read_held(self, most: int) -> None:
        """Read the paused socket (see :meth:`hold`): again while each read
        fills its buffer, up to ``most`` bytes."""
        p = self._protocol
        taken = 0
        while self._fd >= 0 and not p.eof and not self._transport.is_closing():
            try:
                data = os.read(self._fd, _HOLD_READ)
            except (BlockingIOError, InterruptedError):
                break  # nothing (more) arrived: the transport waits for it
            except OSError as exc:  # the transport meets the error or EOF on resuming
                p.error = p.error or exc
                break
            if not data:
                break
            self.held_reads += 1
            p.chunks.append(data)
            p.buffered += len(data)
            taken += len(data)
            if len(data) < _HOLD_READ or taken >= most:
                break
        if not taken:
            self._resume_held()

    def _resume_held(self) -> None:
        p = self._protocol
        p.held = False
        if p.read_paused and not self._transport.is_closing():
            p.read_paused = False
            self._transport.resume_reading()

    async def send(self, item: bytes) -> None:
        if self._closed:
            raise anyio.ClosedResourceError
        p = self._protocol
        if p.error is not None or self._transport.is_closing():
            raise anyio.BrokenResourceError from p.error
        self._transport.write(item)
        # the socket's buffer is over its high-water mark: wait until it
        # drains, or until the connection is closed (then the data is lost)
        while p.write_paused:
            fut: asyncio.Future[None] = p.loop.create_future()
            p.drainers.append(fut)
            await fut
            if self._closed:
                raise anyio.ClosedResourceError
            if p.error is not None or self._transport.is_closing():
                raise anyio.BrokenResourceError from p.error

    def write_nowait(self, data: bytes) -> bool:
        """Write ``data`` at once if that needs no wait: the stream is open
        and the transport is under its high-water mark. True when written
        (the transport sends it or buffers it, as :meth:`send` does); False
        when nothing was written, and :meth:`send` (which may wait, and
        raises what the stream's state says) is the way. A write that takes
        the transport over its high-water mark is made: the next
        :meth:`send` waits for the drain, as after :meth:`send`'s own
        write."""
        p = self._protocol
        if (
            self._closed
            or p.write_paused
            or p.error is not None
            or not data
            or self._transport.is_closing()
        ):
            return False
        self._transport.write(data)
        return True

    async def send_eof(self) -> None:
        if self._closed:
            raise anyio.ClosedResourceError
        if not self._transport.is_closing():
            self._transport.write_eof()

    async def aclose(self) -> None:
        """Close the socket at once, discarding what is not yet written (a
        write stuck on a peer that stopped reading ends here); never raises."""
        self._closed = True
        if not self._transport.is_closing():
            with contextlib.suppress(OSError):
                self._transport.write_eof()
            self._transport.close()
        self._transport.abort()
        self._protocol.wake_reader()
        self._protocol.wake_drainers()


async def connect_tcp(host: str, port: int) -> ProtocolStream:
    """Connect to ``host:port`` on the running asyncio loop (``OSError`` on
    failure, as ``anyio.connect_tcp`` raises)."""
    loop = asyncio.get_running_loop()
    transport, protocol = await loop.create_connection(lambda: _Protocol(loop), host, port)
    return ProtocolStream(transport, protocol)  # (typed Transport; on uvloop not a subclass)
