"""The WebSocket reader's trio side (imported on trio only): a sleep that ends
without an exception, and reads of trio's plain TCP socket without anyio's
stream layers.

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

import socket
from typing import Final

import anyio
import trio
import trio.lowlevel

__all__ = ["READ_SIZE", "receive", "receive_into", "sleep", "sleep_until"]

READ_SIZE: Final = 64 * 1024
"""The most bytes one :func:`receive` asks for. trio's own read allocates a
buffer of the size asked and shrinks it to what came: 1 MiB is above the C
allocator's threshold for a fresh mapping of memory, so each such read
faulted in every page it filled (about 180 page faults per camera image);
64 KiB is reused memory. A large frame's rest is read straight into its
buffer (:func:`receive_into`), whatever this size."""

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


async def receive(sock: socket.socket) -> bytes:
    """At most :data:`READ_SIZE` bytes of ``sock``: anyio's ``receive`` without its
    layers (a cancellation check, then a non-blocking read that usually
    finds nothing, then the wait): wait until trio reports the socket
    readable (always a checkpoint), then read once. Raises as the stream
    does: ``EndOfStream`` at the peer's EOF, ``anyio.ClosedResourceError``
    once the socket is closed (also while waiting), ``OSError`` when the
    read fails."""
    while True:
        if sock.fileno() < 0:
            raise anyio.ClosedResourceError
        try:
            await trio.lowlevel.wait_readable(sock)
        except trio.ClosedResourceError as exc:  # closed while waiting
            raise anyio.ClosedResourceError from exc
        try:
            data = sock.recv(READ_SIZE)
        except (BlockingIOError, InterruptedError):
            continue  # readable, then not (another reader took it): wait again
        if not data:
            raise anyio.EndOfStream
        return data


async def receive_into(sock: socket.socket, view: memoryview) -> tuple[int, bool]:
    """Read ``sock`` into ``view``, at once when it holds bytes, else once it
    is readable: ``(count read, whether it waited)``. No checkpoint after a
    read that did not wait: the caller records the bytes first, then makes
    one (a cancellation there must not lose them). Raises as
    :func:`receive`."""
    waited = False
    while True:
        try:
            n = sock.recv_into(view)
        except (BlockingIOError, InterruptedError):
            try:
                await trio.lowlevel.wait_readable(sock)
            except trio.ClosedResourceError as exc:
                raise anyio.ClosedResourceError from exc
            waited = True
            continue
        if not n:
            raise anyio.EndOfStream
        return n, waited
