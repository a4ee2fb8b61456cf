"""A WebSocket client connection: ``websockets``' sans-IO client protocol driven
by an anyio byte stream, so one implementation serves asyncio and trio.

The connection is used by exactly one reader task (:meth:`WebSocket.receive`)
and any number of writers (:meth:`WebSocket.send`), serialised by a lock so
frames never interleave. Keep-alive is WebSocket ping/pong
(:meth:`WebSocket.keepalive`, run as a task by the owner).

On asyncio's plain TCP stream the owner may also take whole data messages
synchronously where they are read (:meth:`WebSocket.handle_inline`): no task
step per message for those it takes."""

from __future__ import annotations

import os
import socket
from collections import deque
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from typing import Final

import anyio
import anyio.abc
import anyio.lowlevel
import sniffio
from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.protocol import State

from .._errors import ConnectError
from . import _asyncio_stream
from ._read_pacing import COALESCE_BELOW, HOLD_DRAIN, ReadPacer

__all__ = [
    "ConnectionLost",
    "InlineHandler",
    "WebSocket",
]

InlineHandler = Callable[[bool, bytes, int, int], bool]
"""``handler(is_text, data, start, stop)``: take the message ``data[start:stop]``
now, or return False (having done nothing) to leave it to the reader."""

READ_CHUNK: Final = 1 << 20
"""The most bytes one read of the stream asks for (the handshake's reads too)."""
_FEED_STEP: Final = 16 * 1024
"""Bytes handed to the WebSocket parser at a time. The parser turns all it is
given into frame objects at once (about 150 bytes of memory each): a 1 MiB
read of 1-byte continuation frames would be 350,000 of them. Fed in steps,
the frames of one step are handled and freed before the next is parsed."""
_FEED_STEP_MAX: Final = 64 * 1024
"""Inside a large frame (a step that completes nothing) the step doubles up
to this: as fast as one step for a camera image, and at most ~22,000 frame
objects (~3 MB) parsed at once whatever follows it."""
_FAST_FRAMES: Final = 1024
"""Data frames the fast path parses before the reader handles them: a 1 MiB
read of empty frames is parsed 1024 at a time, never 500,000 at once."""
_ASSEMBLE_FROM: Final = 64 * 1024
"""A data frame of this many bytes or more that is not complete in the bytes
at hand is gathered as the chunks that carry it (kept as they came, no copy)
and joined once, when its last byte arrives, into one ``bytes`` of its exact
size: one copy and one buffer of the frame's size per frame, where growing the
unparsed-bytes buffer and cutting the frame out of it cost two copies, a
buffer regrown to the frame's size and shrunk again, per camera image."""
_DIRECT_MAX: Final = 8 * 1024 * 1024
"""On a plain TCP socket (asyncio's :class:`~._asyncio_stream.ProtocolStream`,
trio's socket) a large data frame (see :data:`_ASSEMBLE_FROM`) up to this many
bytes is read straight from the socket into one buffer the connection keeps
for the next one (:meth:`WebSocket._read_direct`), then copied once into its
``bytes``: no fresh read buffer per socket read (each new memory to fault
in). The kept buffer is the largest such frame's size, so at most this many
bytes per connection; a larger frame is gathered chunk by chunk."""
_OP_TEXT: Final = 0x1
_OP_BINARY: Final = 0x2
_OP_PONG: Final = 0xA
_FIN_TEXT: Final = 0x81
_FIN_BINARY: Final = 0x82
_INLINE_BATCH: Final = 64
"""Messages one read may hand to the inline handler (:meth:`WebSocket.handle_inline`)."""
_CONTROL_OPCODES: Final = (0x8, 0x9, 0xA)
"""Close, ping, pong: the control frames websockets accepts."""


class ConnectionLost(ConnectError):
    """The WebSocket closed: by the peer, by a protocol error, by a frame above
    the size limit, or by a missed keep-alive. ``code`` and ``reason`` are the
    close code and reason when a close frame was exchanged (the server's when
    it closed: ``connection closed by server: 1011 bridge crashed``), else
    ``None``."""

    def __init__(self, message: str, code: int | None = None, reason: str | None = None) -> None:
        self.code = code
        self.reason = reason
        super().__init__(message)


@dataclass(slots=True)
class _Pending:
    """A fragmented message being reassembled into one buffer."""

    opcode: Opcode
    data: bytearray


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
        self._max_size = max_size
        self._send_lock = anyio.Lock(fast_acquire=True)
        self._messages: deque[tuple[bool, bytes | bytearray]] = deque()
        self._fragment: _Pending | None = None
        self._fast = True  # False once websockets' parser holds part of a frame
        self._buf = bytearray()  # the fast path's unparsed bytes
        self._more = False  # the fast path stopped at _FAST_FRAMES with bytes left
        # a large data frame being gathered (see _ASSEMBLE_FROM): its chunks,
        # the bytes still missing, and whether it is text
        self._parts: list[bytes | bytearray | memoryview] | None = None
        self._missing = 0
        self._parts_text = False
        # the large frame being read straight into _direct_buf (a plain TCP
        # socket, either loop), as a view of its exact size, and how much of
        # it is filled
        self._direct: memoryview | None = None
        self._direct_buf = bytearray()
        self._filled = 0
        self.direct_frames = 0
        """Large frames read straight into the connection's kept buffer
        (a plain TCP socket; see :data:`_DIRECT_MAX`)."""
        self._inline: InlineHandler | None = None
        self.inline_messages = 0
        """Messages taken by the :meth:`handle_inline` handler so far."""
        self._pongs: dict[bytes, anyio.Event] = {}
        self._closed_reason: ConnectionLost | None = None
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
        self._direct_reads = self._held_sock is not None or self._protocol_stream is not None
        self.reads = 0
        """Reads from the socket so far (each one wake-up of the reader)."""
        self._held_reads = 0
        self.bytes_received = 0
        """Bytes read from the socket so far (WebSocket framing included; the
        handshake's too when :func:`connect_websocket` opened it)."""
        self.messages_received = 0
        """Messages :meth:`receive_raw` and :meth:`receive_ready` returned so far."""
        self.close_timeout = 1.0
        """Seconds the peer gets to end the TCP connection once the close
        handshake is done (or we failed the connection) before the client
        closes it: a server that sends a close frame and keeps the socket
        open cannot hold the reader."""
        for frame in frames:
            self._on_frame(frame)

    # -- receiving ---------------------------------------------------------
    def handle_inline(self, handler: InlineHandler | None) -> None:
        """Offer whole data messages to ``handler`` as soon as they are read,
        ahead of :meth:`receive_raw` (None: stop). On asyncio's plain TCP
        stream that is in the event loop's read callback, while the reader
        task waits with nothing buffered, and in the timer's callback that
        ends the reader's wait before a read (read coalescing, a hold: see
        :mod:`._read_pacing`): a message taken there costs no task step, and
        a read taken whole at the end of a wait starts the next wait from
        the callback (counted in :attr:`paced_reads`). Elsewhere (trio, TLS)
        the reader offers them right after its read, before any message
        object is built.

        Only an unfragmented, unmasked text or binary frame with a length
        below 64 KiB that starts a read, or follows taken ones in it, is
        offered, while nothing waits for :meth:`receive_raw`, websockets'
        parser holds nothing and the connection is open; at most
        :data:`_INLINE_BATCH` per read, so a large burst still reaches the
        reader, which lets consumers run between its batches. Anything else
        (a control frame, a partial frame) and everything after it in the
        read goes to the reader, in order. A handler that raises is removed;
        the message goes to the reader."""
        self._inline = handler
        stream = self._protocol_stream
        if stream is not None:
            stream.inline = None if handler is None else self._take_read
            stream.paced = None if handler is None else self._paced_read

    def _paced_read(self, data: bytes) -> tuple[int, float]:
        """:attr:`ProtocolStream.paced`: a read made at the end of a wait
        before a read, offered to the inline handler; the bytes taken, and
        how long to wait before the next read when all were taken (0.0:
        the reader reads next)."""
        before = self.inline_messages
        taken = self._take_inline(data)
        self.bytes_received += taken
        if taken < len(data):
            return taken, 0.0
        self.reads += 1
        pacer = self._pacer
        pacer.after_read(len(data), True, self.inline_messages - before)
        delay, holding = pacer.delay(bool(self._pongs))
        if delay <= 0:
            return taken, 0.0
        pacer.waited(holding)
        return taken, delay

    def _take_read(self, data: bytes) -> int:
        """:attr:`ProtocolStream.inline`: :meth:`_take_inline`, unless the
        reader must take the read (see :meth:`.ReadPacer.inline_time`: reads
        come faster than :attr:`read_coalesce`, or a hold is due). A read
        taken whole counts in :attr:`reads`."""
        pacer = self._pacer
        now = pacer.inline_time(len(data), bool(self._pongs))
        if now is None:
            return 0
        taken = self._take_inline(data)
        self.bytes_received += taken  # (the rest is counted by the reader's read)
        if taken == len(data):
            self.reads += 1
            pacer.read_taken(now)
        return taken

    def _take_inline(self, data: bytes) -> int:
        """:attr:`ProtocolStream.inline`: how many leading bytes of ``data``
        the inline handler took (see :meth:`handle_inline`)."""
        handler = self._inline
        if (
            handler is None
            or not self._fast
            or self._buf
            or self._messages
            or self._more
            or self._parts is not None  # the read continues a large frame
            or self._direct is not None
            or self._fragment is not None
            or self._closed_reason is not None
            or self._proto.state is not State.OPEN
        ):
            return 0
        max_size = self._max_size
        end = len(data)
        pos = 0
        taken = 0
        while end - pos >= 2 and taken < _INLINE_BATCH:
            b0 = data[pos]
            b1 = data[pos + 1]
            if b0 != _FIN_BINARY and b0 != _FIN_TEXT:
                break
            if b1 < 126:  # (also: not masked)
                start = pos + 2
                length = b1
            elif b1 == 126:
                if end - pos < 4:
                    break
                start = pos + 4
                length = (data[pos + 2] << 8) | data[pos + 3]
            else:  # 64-bit length or masked: the reader's
                break
            stop = start + length
            if stop > end or (max_size is not None and length > max_size):
                break
            try:
                took = handler(b0 == _FIN_TEXT, data, start, stop)
            except Exception:
                self.handle_inline(None)  # a bug: the reader handles it, and reports it
                break
            if not took:
                break
            taken += 1
            pos = stop
        self.inline_messages += taken
        self.messages_received += taken
        return pos

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
            if self._more:  # whole frames still wait in the fast path's buffer
                self._more = False
                self._feed(b"")
                await self._flush()
                continue
            if self._closed_reason is not None:
                await self._finish_closing()
                raise self._closed_reason
            direct = self._direct is not None
            pacer = self._pacer
            held = not direct and pacer.active and await pacer.wait(bool(self._pongs))
            sock = self._held_sock
            try:
                if direct:
                    await self._read_direct()
                    continue
                data = b""
                if held and sock is not None:
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
                self._lost(
                    ConnectionLost(
                        f"connection lost: {exc!r}" if str(exc) else "connection closed by peer"
                    )
                )
                await self._finish_closing()
                raise self._closed_reason from exc  # type: ignore[misc]
            self.reads += 1
            self.bytes_received += len(data)
            nbytes = len(data)
            inline = self.inline_messages
            if self._inline is not None and (taken := self._take_inline(data)):
                data = data[taken:]
            if data:
                self._feed(data)
            pacer.after_read(nbytes, held, len(messages) + self.inline_messages - inline)
            if data:
                await self._flush()  # pongs, close replies: usually nothing, and then no lock
            elif self._stream_buffered():
                # all taken inline, and more is buffered (a burst read in many
                # chunks): the consumers get a turn first (anyio's streams
                # checkpoint in every receive)
                await anyio.lowlevel.checkpoint()
        self.messages_received += 1
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
        self.messages_received += len(ready)
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
        (see :data:`_DIRECT_MAX`); queues it as one ``bytes`` once whole.
        Waits for the socket when it has nothing; on trio it otherwise yields
        to the scheduler after the read, as anyio's ``receive`` does. Raises
        as the stream's ``receive`` does (``EndOfStream`` at the end of the
        stream, ``OSError`` on an error)."""
        view = self._direct
        assert view is not None
        filled = self._filled
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
        filled += n
        if filled == len(view):
            self._direct = None
            self._filled = 0
            self.direct_frames += 1
            self._messages.append((self._parts_text, bytes(view)))  # its one copy
            view.release()
        else:
            self._filled = filled
        if not waited:
            await anyio.lowlevel.checkpoint()

    @property
    def paced_reads(self) -> int:
        """Reads made at the end of a wait before a read and taken whole by
        the :meth:`handle_inline` handler in the loop's timer callback, with
        no task step (asyncio's plain TCP stream; 0 elsewhere)."""
        stream = self._protocol_stream
        return 0 if stream is None else stream.paced_reads

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

    def _feed(self, data: bytes) -> None:
        """Parse ``data`` and handle its frames.

        The fast path (:meth:`_feed_fast`) takes whole unfragmented data
        frames itself and hands websockets' protocol every other frame, so
        websockets' state machine and checks stay in charge of all but the
        common case. Whatever the fast path does not take goes to websockets
        :data:`_FEED_STEP` bytes at a time, so the frames parsed and not yet
        handled stay few however small they are. A large frame costs no extra
        copy: the parser accumulates its bytes in its own buffer either way."""
        if self._fast:
            data = self._feed_fast(data)
            if not data:
                return
        proto = self._proto
        if len(data) <= _FEED_STEP:
            proto.receive_data(data)
            self._take_events()
            return
        view = memoryview(data)
        start, end, step = 0, len(data), _FEED_STEP
        while start < end:
            proto.receive_data(view[start : start + step])  # type: ignore[arg-type]
            start += step
            if proto.events:
                self._take_events()
                step = _FEED_STEP
            elif step < _FEED_STEP_MAX:  # inside a large frame
                step *= 2
        self._take_events()

    def _feed_fast(self, data: bytes) -> bytes:
        """The fast path for data frames; returns the bytes websockets must
        parse from now on (usually none).

        A frame with FIN, no RSV bit, not masked, opcode text or binary, within
        ``max_size``, outside a fragmented message and while the connection is
        open, is cut out of the bytes here and queued as a message: what
        websockets would do with it, without its generator-based parser (one
        of :data:`_ASSEMBLE_FROM` bytes or more that is not all there yet is
        gathered by :meth:`_gather` as its chunks arrive). A whole control
        frame (ping, pong, close: at most 125 bytes) is handed to websockets
        on its own, so it answers pings and runs the closing handshake. Anything else (a fragment, a masked frame, a reserved
        opcode or bit, a frame over ``max_size``, any byte after the
        connection left OPEN) ends the fast path for this connection: from
        that frame on, websockets parses everything, and fails the
        connection where it must."""
        buf = self._buf
        view: bytes | bytearray
        pos = 0
        if self._parts is not None:  # the rest of a large frame (buf is empty)
            pos = self._gather(data)
            if self._parts is not None:
                return b""
        if buf:
            buf += data
            view = buf
        else:
            view = data
        end = len(view)
        frames = 0
        messages = self._messages
        proto = self._proto
        max_size = self._max_size
        while end - pos >= 2:
            if frames >= _FAST_FRAMES:
                self._more = True
                break
            b0 = view[pos]
            b1 = view[pos + 1]
            opcode = b0 & 0x0F
            # decided on the first two bytes, as websockets decides (it fails a
            # masked frame or a reserved opcode before any length byte arrives)
            plain = (b0 & 0xF0) == 0x80 and b1 < 0x80  # FIN, no RSV bit, not masked
            if (
                plain
                and opcode in (_OP_BINARY, _OP_TEXT)
                and self._fragment is None
                and proto.state is State.OPEN
            ):
                length = b1
                start = pos + 2
                if length == 126:
                    if end - pos < 4:
                        break
                    length = (view[pos + 2] << 8) | view[pos + 3]
                    start = pos + 4
                elif length == 127:
                    if end - pos < 10:
                        break
                    length = int.from_bytes(view[pos + 2 : pos + 10], "big")
                    start = pos + 10
                if max_size is None or length <= max_size:
                    stop = start + length
                    if stop > end:  # the rest of the frame is still on its way
                        if length < _ASSEMBLE_FROM:
                            break
                        self._parts_text = opcode == _OP_TEXT
                        if self._direct_reads and length <= _DIRECT_MAX:
                            # read straight into its buffer from here
                            self._start_direct(length, view, start, end)
                            buf.clear()
                            return b""
                        # gathered chunk by chunk from here (see _ASSEMBLE_FROM)
                        first = view[start:] if view is buf else memoryview(view)[start:]
                        self._parts = [first]
                        self._missing = stop - end
                        buf.clear()
                        return b""
                    messages.append((opcode == _OP_TEXT, view[start:stop]))
                    pos = stop
                    frames += 1
                    continue
            elif plain and opcode in _CONTROL_OPCODES and b1 <= 125:
                stop = pos + 2 + b1
                if stop > end:
                    break
                if opcode == _OP_PONG and proto.state is State.OPEN:
                    # a pong changes nothing in websockets' state: matched to
                    # its ping here, without its parser (a keep-alive's cost)
                    event = self._pongs.pop(bytes(view[pos + 2 : stop]), None)
                    if event is not None:
                        event.set()
                    pos = stop
                    continue
                # a whole control frame: websockets' parser holds nothing after it
                proto.receive_data(bytes(view[pos:stop]))
                self._take_events()
                pos = stop
                if proto.state is State.OPEN and self._closed_reason is None:
                    continue
            # websockets takes over for good
            self._fast = False
            rest = bytes(view[pos:])
            buf.clear()
            return rest
        if pos == end:
            buf.clear()
        elif view is buf:
            del buf[:pos]
        else:
            buf += view[pos:]
        return b""

    def _start_direct(self, length: int, data: bytes | bytearray, start: int, end: int) -> None:
        """Begin reading a large frame of ``length`` bytes straight into the
        kept buffer (grown to ``length`` when smaller), its first bytes
        ``data[start:end]`` copied in."""
        if len(self._direct_buf) < length:
            self._direct_buf = bytearray()  # (free the old one before the new)
            self._direct_buf = bytearray(length)
        view = memoryview(self._direct_buf)[:length]
        view[: end - start] = memoryview(data)[start:end]
        self._direct = view
        self._filled = end - start

    def _gather(self, data: bytes) -> int:
        """Add ``data`` to the large frame being gathered; once it is whole,
        queue it as one ``bytes``. Returns how many bytes of ``data`` the
        frame took (the rest is the next frame's)."""
        parts = self._parts
        assert parts is not None
        missing = self._missing
        size = len(data)
        if size < missing:
            if size:
                parts.append(data)
                self._missing = missing - size
            return size
        parts.append(memoryview(data)[:missing] if size > missing else data)
        self._parts = None
        self._messages.append((self._parts_text, b"".join(parts)))  # its one copy
        return missing

    def _take_events(self) -> None:
        for event in self._proto.events_received():
            if isinstance(event, Frame):
                self._on_frame(event)
        proto = self._proto
        if self._closed_reason is not None:
            return
        rcvd = proto.close_rcvd
        if rcvd is not None:
            # The server closed (websockets has queued our answer). The
            # connection is over now: whether the server then ends TCP or not
            # is bounded by close_timeout in _finish_closing.
            if rcvd.code == 1005:  # an empty close frame
                text = "connection closed by server (no close code)"
            else:
                text = f"connection closed by server: {rcvd.code} {rcvd.reason}".rstrip()
            self._lost(ConnectionLost(text, rcvd.code, rcvd.reason))
        elif proto.state is State.CLOSED:
            self._lost(ConnectionLost(f"connection closed: {proto.close_exc}"))
        elif proto.state is State.CLOSING and proto.close_rcvd is None and proto.close_sent:
            # We failed the connection (a frame over the size limit, a
            # protocol error): it is over now, whether or not the peer ever
            # closes its side.
            sent = proto.close_sent
            self._lost(
                ConnectionLost(
                    f"connection failed: {sent.code} {sent.reason}", sent.code, sent.reason
                )
            )

    def _on_frame(self, frame: Frame) -> None:
        op = frame.opcode
        # websockets hands each frame a fresh bytes or bytearray (a slice of
        # its read buffer), so it is kept as is: no copy per frame
        data = frame.data if isinstance(frame.data, bytes | bytearray) else bytes(frame.data)
        if op is Opcode.TEXT or op is Opcode.BINARY:
            if frame.fin:
                self._messages.append((op is Opcode.TEXT, data))
            else:
                # one growing buffer: a list of parts would cost an object
                # per fragment, however small (a 1-byte fragment: ~40 bytes)
                self._fragment = _Pending(op, bytearray(data))
        elif op is Opcode.CONT:
            pending = self._fragment
            if pending is None:  # websockets rejects this already; be defensive
                return
            buffer = pending.data
            buffer += data
            if self._max_size is not None and len(buffer) > self._max_size:
                # websockets enforces max_size on the whole message already
                self._fragment = None
                self._proto.fail(1009, f"message over {self._max_size} bytes")
                return
            if frame.fin:
                self._fragment = None
                self._messages.append((pending.opcode is Opcode.TEXT, buffer))
        elif op is Opcode.PONG:
            event = self._pongs.pop(bytes(data), None)
            if event is not None:
                event.set()

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

    def _lost(self, reason: ConnectionLost) -> None:
        if self._closed_reason is None:
            self._closed_reason = reason
        for event in self._pongs.values():
            event.set()
        self._pongs.clear()

    @property
    def closed(self) -> bool:
        """True once the connection has closed, for any reason."""
        return self._closed_reason is not None or self._proto.state is State.CLOSED

    # -- sending -----------------------------------------------------------
    async def send(self, message: str | bytes | bytearray | memoryview) -> None:
        """Send one message: text for ``str``, binary otherwise. Raises
        :class:`ConnectionLost` when the connection is gone."""
        async with self._send_lock:
            if self._closed_reason is not None:
                raise self._closed_reason
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
        deadline; past that the connection is failed, never left corrupt."""
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
                    self._lost(ConnectionLost(f"connection lost while sending: {exc!r}"))
                    raise self._closed_reason from exc  # type: ignore[misc]
        if scope.cancelled_caught:
            self._lost(ConnectionLost(f"send did not complete within {limit - now:.3g} s", 1011))
            await self._close_stream()
            raise self._closed_reason  # type: ignore[misc]

    async def ping(self) -> anyio.Event:
        """Send a ping; the returned event is set when its pong arrives (or the
        connection closes). The reader task must be running to see the pong."""
        payload = os.urandom(4)
        event = anyio.Event()
        self._pongs[payload] = event
        self.end_hold()  # the pong is read as it comes
        try:
            async with self._send_lock:
                if self._closed_reason is not None or self._proto.state is not State.OPEN:
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
            if self._closed_reason is not None:
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
                self._lost(ConnectionLost(text, 1011))
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
                if self._proto.state is State.OPEN and self._closed_reason is None:
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
                await self._discard_until_closed(lambda: self._closed_reason is not None)
        self._lost(ConnectionLost("connection closed by client", code))
        await self._close_stream()


def _on_trio() -> bool:
    try:
        return sniffio.current_async_library() == "trio"
    except sniffio.AsyncLibraryNotFoundError:
        return False
