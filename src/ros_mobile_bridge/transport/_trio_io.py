"""The WebSocket reader's trio side (imported on trio only): reads of trio's
plain TCP socket without anyio's stream layers. (Its waits between reads are
a :class:`.._loop._trio_wakeup.TrioWakeup`.)
"""

from __future__ import annotations

import socket
from typing import Final

import anyio
import trio
import trio.lowlevel

__all__ = ["READ_SIZE", "read_ready", "receive", "receive_into"]

READ_SIZE: Final = 64 * 1024
"""The most bytes one :func:`receive` asks for. trio's own read allocates a
buffer of the size asked and shrinks it to what came: 1 MiB is above the C
allocator's threshold for a fresh mapping of memory, so each such read
faulted in every page it filled (about 180 page faults per camera image);
64 KiB is reused memory. A large frame's rest is read straight into its
buffer (:func:`receive_into`), whatever this size."""


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


def read_ready(sock: socket.socket, most: int) -> bytes:
    """What ``sock`` holds now, without waiting (after the reader's wait
    before a read: the bytes that gathered meanwhile): reads of
    :data:`READ_SIZE` bytes, again while each fills its buffer, up to
    ``most`` bytes; b"" when it holds nothing or at the end of the stream
    (:func:`receive` then waits or reports it). Other errors raise
    ``OSError``."""
    parts: list[bytes] = []
    taken = 0
    while True:
        try:
            data = sock.recv(READ_SIZE)  # (no fresh memory mapping per read)
        except (BlockingIOError, InterruptedError):
            break
        if not data:
            break
        parts.append(data)
        taken += len(data)
        if len(data) < READ_SIZE or taken >= most:
            break
    return parts[0] if len(parts) == 1 else b"".join(parts)
