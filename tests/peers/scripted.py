"""A scripted WebSocket server, for the faults no real peer can be made to
commit: garbage frames, unknown ops, truncated binary frames, a socket that
never greets, a close in the middle of the handshake.

It runs on anyio (so on asyncio and trio alike) with websockets' sans-IO
server protocol. A script is an async function taking a :class:`Peer`."""

from __future__ import annotations

from collections.abc import AsyncIterator, Awaitable, Callable, Sequence
from contextlib import asynccontextmanager

import anyio
import anyio.abc
from websockets.frames import Frame, Opcode
from websockets.http11 import Request
from websockets.protocol import State
from websockets.server import ServerProtocol
from websockets.typing import Subprotocol


class Peer:
    """One accepted connection, from the server's side."""

    def __init__(self, stream: anyio.abc.ByteStream, proto: ServerProtocol) -> None:
        self.stream = stream
        self.proto = proto
        self._frames: list[str | bytes] = []

    async def _flush(self) -> None:
        for chunk in self.proto.data_to_send():
            if chunk:
                await self.stream.send(chunk)
            else:  # the protocol ends the TCP stream (after a close, or a failure)
                await self.stream.send_eof()

    async def send_text(self, text: str) -> None:
        self.proto.send_text(text.encode())
        await self._flush()

    async def send_binary(self, data: bytes) -> None:
        self.proto.send_binary(data)
        await self._flush()

    async def send_raw(self, data: bytes) -> None:
        """Bytes straight onto the TCP stream, bypassing WebSocket framing."""
        await self.stream.send(data)

    def stop_reading(self) -> None:
        """Read nothing more from the socket, so the client's writes fill the
        kernel's buffers and stall. On trio nothing reads unless ``recv`` is
        called; anyio's asyncio stream can be left reading into its own
        queue after a receive that found data waiting, so its transport is
        paused here (a private attribute: this is a test peer)."""
        transport = getattr(self.stream, "_transport", None)
        if transport is not None:
            transport.pause_reading()

    async def recv(self) -> str | bytes:
        """The next data message from the client (pings are answered).
        ``anyio.EndOfStream`` once the connection is closed."""
        while not self._frames:
            if self.proto.state is State.CLOSED:
                raise anyio.EndOfStream
            data = await self.stream.receive()
            self.proto.receive_data(data)
            for event in self.proto.events_received():
                if isinstance(event, Frame):
                    if event.opcode is Opcode.TEXT:
                        self._frames.append(bytes(event.data).decode())
                    elif event.opcode is Opcode.BINARY:
                        self._frames.append(bytes(event.data))
            await self._flush()
        return self._frames.pop(0)

    async def drain(self) -> list[str | bytes]:
        """Everything the client sends until it closes the connection."""
        got: list[str | bytes] = []
        try:
            while True:
                got.append(await self.recv())
        except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
            return got


Script = Callable[[Peer], Awaitable[None]]


@asynccontextmanager
async def scripted_server(
    script: Script,
    *,
    subprotocols: Sequence[str] = ("foxglove.sdk.v1.1",),
    handshake: bool = True,
) -> AsyncIterator[str]:
    """Serve ``script`` to every client on 127.0.0.1; yields the ``ws://`` URL.

    With ``handshake=False`` the script gets the raw TCP stream before any
    HTTP upgrade (``peer.proto`` is still created but unused), for faults
    during the handshake itself."""
    listener = await anyio.create_tcp_listener(local_host="127.0.0.1", local_port=0)
    port = listener.extra(anyio.abc.SocketAttribute.local_port)

    async def serve(stream: anyio.abc.SocketStream) -> None:
        proto = ServerProtocol(
            subprotocols=[Subprotocol(s) for s in subprotocols] or None, max_size=None
        )
        peer = Peer(stream, proto)
        async with stream:
            try:
                if handshake:
                    request: Request | None = None
                    while request is None:
                        proto.receive_data(await stream.receive())
                        for event in proto.events_received():
                            if isinstance(event, Request):
                                request = event
                    proto.send_response(proto.accept(request))
                    await peer._flush()
                await script(peer)
            except (anyio.EndOfStream, anyio.BrokenResourceError, anyio.ClosedResourceError):
                pass

    # The listener is closed only after the task group has ended: closing it
    # while ``serve`` is still in ``accept()`` makes that raise
    # ClosedResourceError (trio) instead of taking the cancellation.
    async with listener:
        async with anyio.create_task_group() as tg:
            tg.start_soon(listener.serve, serve)
            try:
                yield f"ws://127.0.0.1:{port}"
            finally:
                tg.cancel_scope.cancel()


SERVER_INFO = (
    '{"op":"serverInfo","name":"scripted","capabilities":["clientPublish","services",'
    '"parameters","parametersSubscribe"],"supportedEncodings":["json","cdr"],"metadata":{}}'
)
