"""A WebSocket client connection: ``websockets``' sans-IO client protocol driven
by an anyio byte stream, so one implementation serves asyncio and trio.

The connection is used by exactly one reader task (:meth:`WebSocket.receive`)
and any number of writers (:meth:`WebSocket.send`), serialised by a lock so
frames never interleave. Keep-alive is WebSocket ping/pong
(:meth:`WebSocket.keepalive`, run as a task by the owner).

The owner may also take whole data messages synchronously where they are
read (:meth:`WebSocket.handle_inline`): no task step per message for those
it takes (on asyncio's plain TCP stream in the loop's callbacks, on trio's
plain socket where the loop ends the reader's wait before a read).

What is read is parsed by the connection's :class:`~._ws_frames.FrameParser`
(no I/O: bytes in, messages out); this module reads, sends, pings and
closes."""

from __future__ import annotations

import os
import socket
from collections.abc import Awaitable, Callable, Iterable
from typing import Final

import anyio
import anyio.abc
import anyio.lowlevel
import sniffio
from websockets.client import ClientProtocol
from websockets.frames import Frame
from websockets.protocol import State

from . import _asyncio_stream
from ._read_pacing import COALESCE_BELOW, HOLD_DRAIN, ReadPacer
from ._ws_frames import ConnectionLost, FrameParser, InlineHandler

__all__ = [
    "ConnectionLost",
    "InlineHandler",
    "WebSocket",
]

READ_CHUNK: Final = 1 << 20
"""The most bytes one read of the stream asks for (the handshake's reads too)."""


class WebSocket:
    """An open client WebSocket. Create it with :func:`connect_websocket`.

    ``frames``: frames ``protocol`` already parsed (those that came in with
    the handshake response), taken as the first ones received."""

    def __init__(
        self,
        stream: anyio.abc.ByteStream,
        protocol: ClientProtocol,
        max_size: int | None,
        *,
        frames: Iterable[Frame] = (),
    ) -> None:
        self._stream = stream
        # asyncio's own stream, or None (an isinstance of an ABC per read costs)
        self._protocol_stream = (
            stream if isinstance(stream, _asyncio_stream.ProtocolStream) else None
        )
        self._proto = protocol
        self._send_lock = anyio.Lock(fast_acquire=True)
        self.subprotocol: str | None = protocol.subprotocol
        self._stream_closed = False
        self.send_timeout = 10.0
        """Seconds one send may take before the connection is declared lost."""
        # when the reader reads: read coalescing and read holds
        self._pacer = ReadPacer(self._protocol_stream)
        # trio's socket under anyio's plain TCP stream: the reader waits for
        # it to be readable and reads it directly (_trio_io.receive), and a
        # read that waited first takes the socket's bytes at once (_trio_io.read_ready)
        self._held_sock: socket.socket | None = None
        # on trio the plain socket is read without anyio's stream layers (_trio_io)
        self._trio_receive: Callable[[socket.socket], Awaitable[bytes]] | None = None
        self._trio_receive_into: (
            Callable[[socket.socket, memoryview], Awaitable[tuple[int, bool]]] | None
        ) = None
        self._trio_read_ready: Callable[[socket.socket, int], bytes] | None = None
        if self._protocol_stream is None and _on_trio():
            from . import _trio_io  # (imports trio: installed, since it runs)

            if isinstance(stream, anyio.abc.SocketStream):
                self._held_sock = stream.extra(anyio.abc.SocketAttribute.raw_socket, None)
                self._trio_receive = _trio_io.receive
                self._trio_receive_into = _trio_io.receive_into
                self._trio_read_ready = _trio_io.read_ready
        # parsing what is read: the parser's deque and pongs bound here too
        # (the same objects), so the reader reaches them in one step
        self._parser = parser = FrameParser(
            protocol,
            max_size,
            self._held_sock is not None or self._protocol_stream is not None,
            lambda: self.handle_inline(None),
            frames,
        )
        self._messages = parser.messages
        self._pongs = parser.pongs
        self.reads = 0
        """Reads from the socket so far (each one wake-up of the reader)."""
        self._held_reads = 0
        self._paced_reads = 0  # trio's (asyncio's stream counts its own)
        # on trio: a read made by the loop at the end of a wait (_trio_due)
        # that the handler did not take whole, for the reader; and whether
        # the loop's read took what the socket held (the reader then waits
        # for more, as on asyncio, instead of reading again at once)
        self._leftover = b""
        self._due_took = False
        self.bytes_received = 0
        """Bytes read from the socket so far (WebSocket framing included; the
        handshake's too when :func:`connect_websocket` opened it)."""
        self._returned = 0  # messages receive_raw and receive_ready returned
        self.close_timeout = 1.0
        """Seconds the peer gets to end the TCP connection once the close
        handshake is done (or we failed the connection) before the client
        closes it: a server that sends a close frame and keeps the socket
        open cannot hold the reader."""

    @property
    def messages_received(self) -> int:
        """Messages :meth:`receive_raw` and :meth:`receive_ready` returned so
        far, and those the :meth:`handle_inline` handler took."""
        return self._returned + self._parser.inline_messages

    @property
    def inline_messages(self) -> int:
        """Messages taken by the :meth:`handle_inline` handler so far."""
        return self._parser.inline_messages

    @property
    def direct_frames(self) -> int:
        """Large frames read straight into the connection's kept buffer
        (a plain TCP socket; see :data:`~._ws_frames._DIRECT_MAX`)."""
        return self._parser.direct_frames

    # -- receiving ---------------------------------------------------------
    def handle_inline(self, handler: InlineHandler | None) -> None:
        """Offer whole data messages to ``handler`` as soon as they are read,
        ahead of :meth:`receive_raw` (None: stop). On asyncio's plain TCP
        stream that is in the event loop's read callback, while the reader
        task waits with nothing buffered, and in the timer's callback that
        ends the reader's wait before a read (read coalescing, a hold: see
        :mod:`._read_pacing`): a message taken there costs no task step, and
        a read taken whole at the end of a wait starts the next wait from
        the callback (counted in :attr:`paced_reads`). On trio's plain
        socket the same goes for the read at the end of such a wait, made
        by the loop where it ends the wait (the loop's shared timer, see
        :mod:`.._loop._trio_timers`); other reads there, and every read over TLS,
        are offered by the reader right after it read them, before any
        message object is built.

        Only an unfragmented, unmasked text or binary frame with a length
        below 64 KiB that starts a read, or follows taken ones in it, is
        offered, while nothing waits for :meth:`receive_raw`, websockets'
        parser holds nothing and the connection is open; at most
        :data:`~._ws_frames._INLINE_BATCH` per read, so a large burst still
        reaches the reader, which lets consumers run between its batches.
        Anything else (a control frame, a partial frame) and everything
        after it in the read goes to the reader, in order. A handler that
        raises is removed; the message goes to the reader."""
        self._parser.inline = handler
        stream = self._protocol_stream
        if stream is not None:
            stream.inline = None if handler is None else self._take_read
            stream.paced = None if handler is None else self._paced_read
        elif self._held_sock is not None:
            self._pacer.due = None if handler is None else self._trio_due

    def _paced_read(self, data: bytes) -> tuple[int, float]:
        """:attr:`ProtocolStream.paced`: a read made at the end of a wait
        before a read, offered to the inline handler; the bytes taken, and
        how long to wait before the next read when all were taken (0.0:
        the reader reads next)."""
        parser = self._parser
        before = parser.inline_messages
        taken = parser.take_inline(data)
        self.bytes_received += taken
        if taken < len(data):
            return taken, 0.0
        self.reads += 1
        pacer = self._pacer
        pacer.after_read(len(data), True, parser.inline_messages - before)
        delay, holding = pacer.delay(bool(self._pongs))
        if delay <= 0:
            return taken, 0.0
        pacer.waited(holding)
        return taken, delay

    def _trio_due(self) -> tuple[float, bool]:
        """:attr:`.ReadPacer.due` on trio's plain socket: the read at the
        end of a wait, made by the loop (:meth:`.._loop._trio_wakeup.TrioWakeup.wait`)
        and offered to the inline handler as asyncio's timer callback does
        (:meth:`_paced_read`); how long the wait goes on, and whether that
        is a hold. A read not taken whole is left for the reader, which
        resumes (as it does when the socket holds nothing or fails: its own
        read meets that)."""
        sock = self._held_sock
        read_ready = self._trio_read_ready
        if sock is None or read_ready is None or self._leftover:
            return 0.0, False
        pacer = self._pacer
        try:
            data = read_ready(sock, HOLD_DRAIN if pacer.drain else COALESCE_BELOW)
        except OSError:
            return 0.0, False
        if not data:
            return 0.0, False
        self._held_reads += 1
        taken, delay = self._paced_read(data)
        if taken < len(data):
            self._leftover = data[taken:] if taken else data
            return 0.0, False
        self._paced_reads += 1
        if delay <= 0.0:
            self._due_took = True
        return delay, pacer.drain

    def _take_read(self, data: bytes) -> int:
        """:attr:`ProtocolStream.inline`: :meth:`.FrameParser.take_inline`,
        unless the reader must take the read (see
        :meth:`.ReadPacer.inline_time`: reads come faster than
        :attr:`read_coalesce`, or a hold is due). A read taken whole counts
        in :attr:`reads`."""
        pacer = self._pacer
        now = pacer.inline_time(len(data), bool(self._pongs))
        if now is None:
            return 0
        taken = self._parser.take_inline(data)
        self.bytes_received += taken  # (the rest is counted by the reader's read)
        if taken == len(data):
            self.reads += 1
            pacer.read_taken(now)
        return taken

    async def receive(self) -> str | bytes | bytearray:
        """The next complete message: ``str`` for text, ``bytes`` or a
        ``bytearray`` that nothing else holds for binary.

        Fragmented messages are reassembled. Raises :class:`ConnectionLost`
        once the connection is closed: messages received before the peer's
        close frame come first, the close is answered, and the peer gets
        :attr:`close_timeout` seconds to end the TCP connection before the
        client ends it."""
        text, data = await self.receive_raw()
        return data.decode() if text else data

    async def receive_raw(self) -> tuple[bool, bytes | bytearray]:
        """The next complete message as ``(is_text, data)``, a text message
        left as its UTF-8 bytes (undecoded and unvalidated: a JSON parser
        reads bytes directly). Otherwise as :meth:`receive`."""
        messages = self._messages
        while not messages:
            parser = self._parser
            if parser.more:  # whole frames still wait in the fast path's buffer
                parser.more = False
                parser.feed(b"")
                await self._flush()
                continue
            if parser.closed_reason is not None:
                await self._finish_closing()
                raise parser.closed_reason
            direct = parser.direct is not None
            pacer = self._pacer
            held = not direct and pacer.active and await pacer.wait(bool(self._pongs))
            sock = self._held_sock
            try:
                if direct:
                    await self._read_direct()
                    continue
                data = self._leftover
                if data:  # the loop read it at the end of the wait (_trio_due)
                    self._leftover = b""
                elif self._due_took:  # ... and took all it read: wait for more
                    self._due_took = False
                elif held and sock is not None:
                    assert self._trio_read_ready is not None
                    data = self._trio_read_ready(
                        sock, HOLD_DRAIN if pacer.drain else COALESCE_BELOW
                    )
                    self._held_reads += bool(data)
                if not data:
                    if sock is not None and self._trio_receive is not None:
                        data = await self._trio_receive(sock)
                    else:
                        data = await self._stream.receive(READ_CHUNK)
            except (
                anyio.EndOfStream,
                anyio.ClosedResourceError,
                anyio.BrokenResourceError,
                OSError,
            ) as exc:
                self._proto.receive_eof()
                lost = parser.lost(
                    ConnectionLost(
                        f"connection lost: {exc!r}" if str(exc) else "connection closed by peer"
                    )
                )
                await self._finish_closing()
                raise lost from exc
            self.reads += 1
            self.bytes_received += len(data)
            nbytes = len(data)
            inline = parser.inline_messages
            if parser.inline is not None and (taken := parser.take_inline(data)):
                data = data[taken:]
            if data:
                parser.feed(data)
            pacer.after_read(nbytes, held, len(messages) + parser.inline_messages - inline)
            if data:
                await self._flush()  # pongs, close replies: usually nothing, and then no lock
            elif self._stream_buffered():
                # all taken inline, and more is buffered (a burst read in many
                # chunks): the consumers get a turn first (anyio's streams
                # checkpoint in every receive)
                await anyio.lowlevel.checkpoint()
        self._returned += 1
        return messages.popleft()

    def receive_ready(self) -> list[tuple[bool, bytes | bytearray]]:
        """Every message already received, oldest first, as :meth:`receive_raw`
        returns each (an empty list when none): never reads, never waits. A
        reader takes what one read brought this way and handles it as one
        batch."""
        messages = self._messages
        if not messages:
            return []
        ready = list(messages)
        messages.clear()
        self._returned += len(ready)
        return ready

    def _stream_buffered(self) -> bool:
        stream = self._protocol_stream
        return stream is not None and stream.has_data

    @property
    def read_coalesce(self) -> float:
        """Seconds a read may wait under a steady stream of small reads so
        that several frames are read and handed over at one wake-up
        (:meth:`receive_raw`); 0 reads as soon as anything arrives. See
        :mod:`._read_pacing`."""
        return self._pacer.window

    @read_coalesce.setter
    def read_coalesce(self, seconds: float) -> None:
        self._pacer.window = seconds

    @property
    def coalesced(self) -> int:
        """Reads that waited for :attr:`read_coalesce` first."""
        return self._pacer.coalesced

    @property
    def quiet_holds(self) -> int:
        """Reads held by :meth:`hold_reads` (the subscriptions' caps)."""
        return self._pacer.quiet_holds

    def hold_reads(self, quiet: Callable[[float], float] | None) -> None:
        """Leave the socket unread while nobody needs what it brings (None:
        stop). ``quiet(now)`` (monotonic seconds) returns the time before
        which no reader of this connection can take a new message, or 0.0;
        the reader asks it before each read (and on asyncio before taking a
        read inline). When that is far enough ahead, the next read waits
        until then, at most a second (counted in :attr:`quiet_holds`; see
        :mod:`._read_pacing`): what arrives meanwhile waits in the kernel
        and is read and handed over together. Never while a ping waits for
        its pong, nor after a read of 64 KiB or more (the socket holds
        more: it is read at once, until a read is smaller). :meth:`end_hold`
        ends a hold at once (the owner calls it when it sends a request
        whose answer must be read)."""
        self._pacer.set_quiet(quiet)

    def end_hold(self) -> None:
        """End the reader's current wait before a read (a hold or read
        coalescing), if it waits: it reads now."""
        self._pacer.end()

    async def _read_direct(self) -> None:
        """One read of the large frame being read straight into its buffer
        (see :data:`~._ws_frames._DIRECT_MAX`); the parser queues it as one
        ``bytes`` once whole (:meth:`.FrameParser.direct_received`).
        Waits for the socket when it has nothing; on trio it otherwise yields
        to the scheduler after the read, as anyio's ``receive`` does. Raises
        as the stream's ``receive`` does (``EndOfStream`` at the end of the
        stream, ``OSError`` on an error)."""
        parser = self._parser
        view = parser.direct
        assert view is not None
        filled = parser.filled
        stream = self._protocol_stream
        waited = True
        if stream is not None:
            n = await stream.receive_into(view[filled:])
        else:
            sock = self._held_sock
            assert sock is not None
            assert self._trio_receive_into is not None
            n, waited = await self._trio_receive_into(sock, view[filled:])
        self.reads += 1
        self.bytes_received += n
        parser.direct_received(n)
        if not waited:
            await anyio.lowlevel.checkpoint()

    @property
    def paced_reads(self) -> int:
        """Reads made at the end of a wait before a read and taken whole by
        the :meth:`handle_inline` handler where the loop ends the wait, with
        no task step (asyncio's plain TCP stream: the timer's callback; trio's
        plain socket: the loop's shared timer; 0 elsewhere)."""
        stream = self._protocol_stream
        return self._paced_reads if stream is None else stream.paced_reads

    @property
    def held_reads(self) -> int:
        """Reads that waited for :attr:`read_coalesce` and then took the
        socket's bytes directly, without a round through the event loop
        (on asyncio the stream reads the paused socket itself, on trio the
        WebSocket reads trio's socket)."""
        stream = self._stream
        if isinstance(stream, _asyncio_stream.ProtocolStream):
            return stream.held_reads
        return self._held_reads

    async def _finish_closing(self) -> None:
        """The connection is over: let the peer end the TCP connection
        (RFC 6455: the server closes first), reading and discarding, for at
        most :attr:`close_timeout` seconds, then close the stream."""
        if self._stream_closed:
            return
        with anyio.move_on_after(self.close_timeout):
            await self._discard_until_closed(lambda: False)
        await self._close_stream()

    async def _discard_until_closed(self, stop: Callable[[], bool]) -> None:
        """Read and discard until the closing handshake completes (or
        ``stop()``), sending what the protocol answers (the close reply);
        the end of the stream or any transport error ends it quietly."""
        proto = self._proto
        try:
            while proto.state is not State.CLOSED and not stop():
                data = await self._stream.receive(READ_CHUNK)
                proto.receive_data(data)
                proto.events_received()
                await self._flush()
        except (
            anyio.EndOfStream,
            anyio.ClosedResourceError,
            anyio.BrokenResourceError,
            OSError,
            ConnectionLost,
        ):
            pass

    async def _close_stream(self) -> None:
        """Close the socket (shielded, never raises). A send blocked on it
        raises at once: closing is how a stuck write is aborted."""
        self._stream_closed = True
        with anyio.CancelScope(shield=True):
            await self._stream.aclose()

    @property
    def closed(self) -> bool:
        """True once the connection has closed, for any reason."""
        return self._parser.closed_reason is not None or self._proto.state is State.CLOSED

    # -- sending -----------------------------------------------------------
    async def send(self, message: str | bytes | bytearray | memoryview) -> None:
        """Send one message: text for ``str``, binary otherwise. Raises
        :class:`ConnectionLost` when the connection is gone."""
        async with self._send_lock:
            closed = self._parser.closed_reason
            if closed is not None:
                raise closed
            if self._proto.state is not State.OPEN:
                raise ConnectionLost("connection is not open")
            if isinstance(message, str):
                self._proto.send_text(message.encode())
            else:
                self._proto.send_binary(message)
            await self._flush_locked()

    async def _flush(self) -> None:
        """Send what the protocol has queued, taking the lock only if anything."""
        chunks = self._proto.data_to_send()
        if chunks:
            async with self._send_lock:
                await self._write(chunks)

    async def _flush_locked(self) -> None:
        chunks = self._proto.data_to_send()
        if chunks:
            await self._write(chunks)

    async def _write(self, chunks: list[bytes]) -> None:
        """Write ``chunks`` (the caller holds the send lock).

        A frame half written is a corrupt connection, so the write itself is
        shielded from cancellation (the cancellation lands right after it).
        It is bounded by ``send_timeout``, or by the caller's own earlier
        deadline; past that the connection is failed, never left corrupt.

        What the connection takes without a wait (:meth:`_write_now`: the
        common case) is written first, with no cancel scope and no timer;
        only the rest goes the way above."""
        chunks = self._write_now(chunks)
        if not chunks:
            return
        now = anyio.current_time()
        limit = now + self.send_timeout
        effective = anyio.current_effective_deadline()
        if now < effective < limit:
            limit = effective
        with anyio.CancelScope(shield=True, deadline=limit) as scope:
            for chunk in chunks:
                try:
                    if chunk:
                        await self._stream.send(chunk)
                    else:
                        await self._stream.send_eof()
                except (anyio.ClosedResourceError, anyio.BrokenResourceError, OSError) as exc:
                    lost = ConnectionLost(f"connection lost while sending: {exc!r}")
                    raise self._parser.lost(lost) from exc
        if scope.cancelled_caught:
            lost = self._parser.lost(
                ConnectionLost(f"send did not complete within {limit - now:.3g} s", 1011)
            )
            await self._close_stream()
            raise lost

    def _write_now(self, chunks: list[bytes]) -> list[bytes]:
        """Write the leading ``chunks`` the connection takes without a wait,
        and return the rest (an end of stream, ``b""``, is always left):
        on asyncio's own stream what
        :meth:`~._asyncio_stream.ProtocolStream.write_nowait` accepts; on
        trio's plain TCP socket what one non-blocking ``send`` takes (a
        partial send leaves the chunk's tail). Elsewhere nothing. An error
        is left for the waiting write to meet and report."""
        stream = self._protocol_stream
        sock = self._held_sock
        if stream is None and sock is None:
            return chunks
        for i, chunk in enumerate(chunks):
            if not chunk:
                return chunks[i:]
            if stream is not None:
                if not stream.write_nowait(chunk):
                    return chunks[i:]
                continue
            assert sock is not None
            try:
                n = sock.send(chunk)
            except OSError:  # full (BlockingIOError), or failed: the waiting write
                return chunks[i:]
            if n < len(chunk):
                return [chunk[n:], *chunks[i + 1 :]]
        return []

    async def ping(self) -> anyio.Event:
        """Send a ping; the returned event is set when its pong arrives (or the
        connection closes). The reader task must be running to see the pong."""
        payload = os.urandom(4)
        event = anyio.Event()
        self._pongs[payload] = event
        self.end_hold()  # the pong is read as it comes
        try:
            async with self._send_lock:
                if self._parser.closed_reason is not None or self._proto.state is not State.OPEN:
                    event.set()
                    return event
                self._proto.send_ping(payload)
                await self._flush_locked()
        except BaseException:
            self._pongs.pop(payload, None)
            raise
        return event

    async def keepalive(
        self,
        interval: float,
        timeout: float,
        on_rtt: Callable[[float], None] | None = None,
    ) -> None:
        """Ping every ``interval`` seconds; fail the connection when a pong has
        not come back within ``timeout``. The timeout runs from when the ping
        is due, so it also counts the wait for a write in progress (a peer
        that stopped reading holds the writer): a dead peer is detected within
        ``interval + timeout`` seconds even then, and failing the connection
        closes the socket, which aborts the stuck write. Each answered ping's
        round trip, in milliseconds, goes to ``on_rtt`` (an idle latency probe
        with no side effect on the server). Returns when the connection
        closes."""
        while not self.closed:
            await anyio.sleep(interval)
            if self._parser.closed_reason is not None:
                return
            sent: float | None = None
            try:
                with anyio.move_on_after(timeout) as scope:
                    pong = await self.ping()
                    sent = anyio.current_time()
                    await pong.wait()
            except ConnectionLost:
                return  # the ping's own write failed the connection; the reader reports it
            if scope.cancelled_caught and not self.closed:
                if sent is None:
                    text = f"keep-alive: the ping could not be sent within {timeout:g} s"
                    text += " (a write is stuck: the peer stopped reading)"
                else:
                    text = f"keep-alive: no pong within {timeout:g} s"
                self._parser.lost(ConnectionLost(text, 1011))
                await self._close_stream()
                return
            if on_rtt is not None and sent is not None and not self.closed:
                on_rtt((anyio.current_time() - sent) * 1000.0)

    async def aclose(self, code: int = 1000, reason: str = "", timeout: float = 1.0) -> None:
        """Close the connection cleanly: send a close frame, wait up to
        ``timeout`` seconds for the peer's, then close the stream. Never
        raises; runs shielded so a cancelled owner still closes the socket."""
        with anyio.CancelScope(shield=True), anyio.move_on_after(timeout):
            try:
                if self._proto.state is State.OPEN and self._parser.closed_reason is None:
                    async with self._send_lock:
                        self._proto.send_close(code, reason)
                        await self._flush_locked()
            except (
                anyio.ClosedResourceError,
                anyio.BrokenResourceError,
                OSError,
                ConnectionLost,
            ):
                pass
            else:
                await self._discard_until_closed(lambda: self._parser.closed_reason is not None)
        self._parser.lost(ConnectionLost("connection closed by client", code))
        await self._close_stream()
        self._leftover = b""
        self._parser.release()


def _on_trio() -> bool:
    try:
        return sniffio.current_async_library() == "trio"
    except sniffio.AsyncLibraryNotFoundError:
        return False
