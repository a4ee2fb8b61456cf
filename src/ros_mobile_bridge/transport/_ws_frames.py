"""The receive side of a :class:`~._websocket.WebSocket` without its I/O:
bytes in, messages out.

:class:`FrameParser` takes the bytes the connection reads
(:meth:`~FrameParser.feed`) and gives what they carry: complete messages, in
order (:attr:`~FrameParser.messages`); pongs matched to the pings waiting for
them (their events in :attr:`~FrameParser.pongs`, set and removed); and, once
the connection is over, why (:attr:`~FrameParser.closed_reason`). It never
reads, writes or awaits: websockets' sans-IO ``ClientProtocol`` queues what
must be sent back (pongs, the close reply) and the owner sends it.

A fast path parses the common frames itself: whole unfragmented, unmasked text
and binary frames within ``max_size`` while the connection is open, and the
whole control frames between them (ping, pong, close: handed to websockets one
at a time, so it answers pings and runs the closing handshake). A large data
frame that spans reads is gathered chunk by chunk, or, when the owner can read
straight into a buffer, completed by the owner's reads into
:attr:`~FrameParser.direct` (:meth:`~FrameParser.direct_received`). The first
frame the fast path does not take (a fragment, a masked frame, a reserved
opcode or bit, a frame over ``max_size``, any byte after the connection left
OPEN) hands the connection to websockets' parser for good: from that frame on
it parses everything, and fails the connection where it must.

Whole small data frames at the start of a read can also be offered to an
inline handler before anything is parsed (:meth:`~FrameParser.take_inline`)."""

from __future__ import annotations

import contextlib
from collections import deque
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Final

import anyio
from websockets.client import ClientProtocol
from websockets.frames import Frame, Opcode
from websockets.protocol import State

from .._errors import ConnectError

__all__ = ["ConnectionLost", "FrameParser", "InlineHandler"]

InlineHandler = Callable[[bool, bytes, int, int], bool]
"""``handler(is_text, data, start, stop)``: take the message ``data[start:stop]``
now, or return False (having done nothing) to leave it to the reader."""

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
for the next one (:attr:`FrameParser.direct`), then copied once into its
``bytes``: no fresh read buffer per socket read (each new memory to fault
in). The kept buffer is the largest such frame's size, so at most this many
bytes per connection; a larger frame is gathered chunk by chunk."""
_OP_TEXT: Final = 0x1
_OP_BINARY: Final = 0x2
_OP_PONG: Final = 0xA
_FIN_TEXT: Final = 0x81
_FIN_BINARY: Final = 0x82
_INLINE_BATCH: Final = 64
"""Messages one read may hand to the inline handler (:meth:`FrameParser.take_inline`)."""
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


class FrameParser:
    """The frame parsing of one WebSocket connection (see the module
    docstring). ``protocol``: the connection's websockets protocol (it parses
    what the fast path does not take, and queues the answers to send);
    ``max_size``: the largest message taken, None for no limit;
    ``direct_reads``: the owner reads a large frame straight into
    :attr:`direct` (a plain TCP socket); ``drop_inline``: called when the
    :attr:`inline` handler raised (the owner stops offering reads to it);
    ``frames``: frames ``protocol`` already parsed (those that came in with
    the handshake response), taken as the first ones received."""

    __slots__ = (
        "_buf",
        "_direct_buf",
        "_direct_reads",
        "_drop_inline",
        "_fast",
        "_fragment",
        "_max_size",
        "_missing",
        "_parts",
        "_parts_text",
        "_proto",
        "closed_reason",
        "direct",
        "direct_frames",
        "filled",
        "inline",
        "inline_messages",
        "messages",
        "more",
        "pongs",
    )

    def __init__(
        self,
        protocol: ClientProtocol,
        max_size: int | None,
        direct_reads: bool,
        drop_inline: Callable[[], None],
        frames: Iterable[Frame] = (),
    ) -> None:
        self._proto = protocol
        self._max_size = max_size
        self._direct_reads = direct_reads
        self._drop_inline = drop_inline
        self.messages: deque[tuple[bool, bytes | bytearray]] = deque()
        """Complete messages as ``(is_text, data)``, oldest first."""
        self._fragment: _Pending | None = None
        self._fast = True  # False once websockets' parser holds part of a frame
        self._buf = bytearray()  # the fast path's unparsed bytes
        self.more = False
        """The fast path stopped at :data:`_FAST_FRAMES` with bytes left:
        ``feed(b"")`` (once this is reset) parses the next ones."""
        # a large data frame being gathered (see _ASSEMBLE_FROM): its chunks,
        # the bytes still missing, and whether it is text
        self._parts: list[bytes | bytearray | memoryview] | None = None
        self._missing = 0
        self._parts_text = False
        self.direct: memoryview | None = None
        """The large frame being read straight into the kept buffer (see
        :data:`_DIRECT_MAX`), a view of its exact size; the owner's reads
        fill it from :attr:`filled` on (:meth:`direct_received`)."""
        self._direct_buf = bytearray()
        self.filled = 0
        """Bytes of :attr:`direct` filled so far."""
        self.direct_frames = 0
        """Large frames read straight into the connection's kept buffer
        (a plain TCP socket; see :data:`_DIRECT_MAX`)."""
        self.inline: InlineHandler | None = None
        """The handler :meth:`take_inline` offers messages to, or None."""
        self.inline_messages = 0
        """Messages taken by the :attr:`inline` handler so far."""
        self.pongs: dict[bytes, anyio.Event] = {}
        """The events of the pings waiting for their pong, by payload: a pong
        sets and removes its ping's, :meth:`lost` all of them."""
        self.closed_reason: ConnectionLost | None = None
        """Why the connection is over (the first reason given), or None."""
        for frame in frames:
            self._on_frame(frame)

    def take_inline(self, data: bytes) -> int:
        """How many leading bytes of ``data``, a read not fed yet, the
        :attr:`inline` handler took: whole small data frames, while nothing
        waits before them (see :meth:`.WebSocket.handle_inline`). The rest
        is :meth:`feed`'s."""
        handler = self.inline
        if (
            handler is None
            or not self._fast
            or self._buf
            or self.messages
            or self.more
            or self._parts is not None  # the read continues a large frame
            or self.direct is not None
            or self._fragment is not None
            or self.closed_reason is not None
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
                # a bug: the reader handles it, and reports it
                self.inline = None
                self._drop_inline()
                break
            if not took:
                break
            taken += 1
            pos = stop
        self.inline_messages += taken
        return pos

    def feed(self, data: bytes) -> None:
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
        messages = self.messages
        proto = self._proto
        max_size = self._max_size
        while end - pos >= 2:
            if frames >= _FAST_FRAMES:
                self.more = True
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
                    event = self.pongs.pop(bytes(view[pos + 2 : stop]), None)
                    if event is not None:
                        event.set()
                    pos = stop
                    continue
                # a whole control frame: websockets' parser holds nothing after it
                proto.receive_data(bytes(view[pos:stop]))
                self._take_events()
                pos = stop
                if proto.state is State.OPEN and self.closed_reason is None:
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
        self.direct = view
        self.filled = end - start

    def direct_received(self, n: int) -> None:
        """The owner read ``n`` more bytes of the large frame into
        ``direct[filled:]``; once it is whole, queue it as one ``bytes`` (and
        :attr:`direct` is None again)."""
        view = self.direct
        assert view is not None
        filled = self.filled + n
        if filled == len(view):
            self.direct = None
            self.filled = 0
            self.direct_frames += 1
            self.messages.append((self._parts_text, bytes(view)))  # its one copy
            view.release()
        else:
            self.filled = filled

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
        self.messages.append((self._parts_text, b"".join(parts)))  # its one copy
        return missing

    def _take_events(self) -> None:
        for event in self._proto.events_received():
            if isinstance(event, Frame):
                self._on_frame(event)
        proto = self._proto
        if self.closed_reason is not None:
            return
        rcvd = proto.close_rcvd
        if rcvd is not None:
            # The server closed (websockets has queued our answer). The
            # connection is over now: whether the server then ends TCP or not
            # is bounded by the owner's close_timeout.
            if rcvd.code == 1005:  # an empty close frame
                text = "connection closed by server (no close code)"
            else:
                text = f"connection closed by server: {rcvd.code} {rcvd.reason}".rstrip()
            self.lost(ConnectionLost(text, rcvd.code, rcvd.reason))
        elif proto.state is State.CLOSED:
            self.lost(ConnectionLost(f"connection closed: {proto.close_exc}"))
        elif proto.state is State.CLOSING and proto.close_rcvd is None and proto.close_sent:
            # We failed the connection (a frame over the size limit, a
            # protocol error): it is over now, whether or not the peer ever
            # closes its side.
            sent = proto.close_sent
            self.lost(
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
                self.messages.append((op is Opcode.TEXT, data))
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
                self.messages.append((pending.opcode is Opcode.TEXT, buffer))
        elif op is Opcode.PONG:
            event = self.pongs.pop(bytes(data), None)
            if event is not None:
                event.set()

    def release(self) -> None:
        """The connection is over and its owner done with it: drop every
        buffer (the kept large-frame buffer, unparsed bytes, a frame being
        gathered, messages nobody will read), and the tracebacks of
        :attr:`closed_reason` and of the exceptions it chains (the read's
        ``EndOfStream`` or ``OSError``). Their frames hold this connection,
        and the reason holds them: a reference cycle that would keep the
        connection and its buffers (a large frame's, about the size of the
        largest message) alive until the cyclic garbage collector's next
        full pass, and for as long as a caller keeps the exception
        (``client.last_error``). The reason itself, its message and its
        ``__cause__`` stay."""
        self.messages.clear()
        self._buf = bytearray()
        self._parts = None
        self._fragment = None
        direct, self.direct = self.direct, None
        if direct is not None:
            with contextlib.suppress(BufferError):  # (still exported: let it go)
                direct.release()
        self._direct_buf = bytearray()
        seen: set[int] = set()
        error: BaseException | None = self.closed_reason
        while error is not None and id(error) not in seen:
            seen.add(id(error))
            error.__traceback__ = None
            error = error.__cause__ or error.__context__

    def lost(self, reason: ConnectionLost) -> ConnectionLost:
        """The connection is over: ``reason`` is why, unless one was given
        before; every wait for a pong ends (its event set). Returns the
        reason that stands (:attr:`closed_reason`)."""
        closed = self.closed_reason
        if closed is None:
            self.closed_reason = closed = reason
        for event in self.pongs.values():
            event.set()
        self.pongs.clear()
        return closed
