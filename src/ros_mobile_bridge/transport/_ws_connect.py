"""Opening a WebSocket: TCP (asyncio's protocol-based stream or anyio's), TLS
and the HTTP upgrade through ``websockets``' sans-IO client, then a
:class:`~ros_mobile_bridge.transport.WebSocket` over the stream. The errors
of a refused handshake are built here for every way of opening one (the
httpx transport too)."""

from __future__ import annotations

import logging
import ssl as _ssl
from collections.abc import Sequence

import anyio
import anyio.abc
import sniffio
from websockets.client import ClientProtocol
from websockets.exceptions import InvalidHandshake, InvalidStatus, InvalidURI
from websockets.frames import Frame
from websockets.http11 import Response
from websockets.typing import Subprotocol
from websockets.uri import parse_uri

from .._errors import ConnectError
from . import _asyncio_stream
from ._websocket import READ_CHUNK, WebSocket

__all__ = ["HandshakeRejected", "client_protocol", "connect_websocket", "handshake_error"]


class HandshakeRejected(ConnectError):
    """The server answered the opening handshake with an HTTP status other than
    101. ``status`` and ``body`` carry its answer (a Foxglove SDK server says
    ``Missing expected sec-websocket-protocol header`` with status 400 to a
    client that offers none of its subprotocols)."""

    def __init__(self, status: int, body: str) -> None:
        self.status = status
        self.body = body
        super().__init__(f"WebSocket handshake rejected with HTTP {status}: {body!r}")


async def connect_websocket(
    url: str,
    *,
    subprotocols: tuple[str, ...] = (),
    max_size: int | None = 1 << 20,
    ssl_context: _ssl.SSLContext | None = None,
    timeout: float = 10.0,
    read_coalesce: float = 0.0,
    headers: Sequence[tuple[str, str]] = (),
    quiet: bool = False,
) -> WebSocket:
    """Open a WebSocket to ``url`` (``ws://`` or ``wss://``) offering
    ``subprotocols``. ``timeout`` covers TCP connect, TLS and the HTTP upgrade.
    ``headers`` are added to the upgrade request as given (the caller
    validates them: :class:`~ros_mobile_bridge.ClientOptions` does).
    websockets' debug log (the handshake's headers, the start of every
    frame) is off for this connection when ``quiet`` is set or there are
    headers, so secrets in either never reach a log.

    Raises :class:`HandshakeRejected` when the server answers with an HTTP
    status, ``ConnectError`` for anything else that prevents the connection
    (refused, unreachable, timeout, TLS failure), ``ValueError`` for a bad URL.
    ``max_size`` bounds one message (``None``: no bound); a larger message
    closes the connection with code 1009. ``read_coalesce`` sets
    :attr:`WebSocket.read_coalesce`."""
    proto = client_protocol(url, subprotocols, max_size, quiet=quiet or bool(headers))
    uri = proto.uri
    stream: anyio.abc.ByteStream | None = None
    try:
        with anyio.fail_after(timeout):
            if uri.secure:
                ctx = ssl_context or _ssl.create_default_context()
                stream = await anyio.connect_tcp(
                    uri.host, uri.port, ssl_context=ctx, tls_standard_compatible=False
                )
            elif sniffio.current_async_library() == "asyncio":
                stream = await _asyncio_stream.connect_tcp(uri.host, uri.port)
            else:
                stream = await anyio.connect_tcp(uri.host, uri.port)
            request = proto.connect()
            for name, value in headers:
                request.headers[name] = value
            proto.send_request(request)
            for chunk in proto.data_to_send():
                await stream.send(chunk)
            response: Response | None = None
            leftover: list[Frame] = []
            received = 0
            while response is None and proto.handshake_exc is None:
                try:
                    data = await stream.receive(READ_CHUNK)
                except anyio.EndOfStream:
                    proto.receive_eof()
                    data = b""
                received += len(data)
                if data:
                    proto.receive_data(data)
                for event in proto.events_received():
                    if isinstance(event, Response):
                        response = event
                    elif isinstance(event, Frame):
                        leftover.append(event)
                if response is None and not data:
                    raise ConnectError(
                        "server closed the connection during the WebSocket handshake"
                    )
    except TimeoutError as exc:
        if stream is not None:
            with anyio.CancelScope(shield=True):
                await stream.aclose()
        raise ConnectError(f"timed out after {timeout:g} s connecting to {url}") from exc
    except (OSError, anyio.BrokenResourceError, _ssl.SSLError) as exc:
        if stream is not None:
            with anyio.CancelScope(shield=True):
                await stream.aclose()
        raise ConnectError(f"cannot connect to {url}: {exc}") from exc
    except BaseException:
        if stream is not None:
            with anyio.CancelScope(shield=True):
                await stream.aclose()
        raise
    if proto.handshake_exc is not None:
        with anyio.CancelScope(shield=True):
            await stream.aclose()
        raise handshake_error(url, proto.handshake_exc) from proto.handshake_exc
    ws = WebSocket(stream, proto, max_size, frames=leftover)
    ws.bytes_received = received
    ws.read_coalesce = read_coalesce
    return ws


class _NoDebug(logging.LoggerAdapter):  # type: ignore[type-arg]
    """websockets' logger without its debug level: its debug log prints
    every request header and the start of every frame, secrets included."""

    def isEnabledFor(self, level: int) -> bool:
        return level > logging.DEBUG and self.logger.isEnabledFor(level)


def client_protocol(
    url: str, subprotocols: tuple[str, ...], max_size: int | None, *, quiet: bool
) -> ClientProtocol:
    """websockets' sans-IO client for ``url`` (``ValueError`` for a bad
    URL); ``quiet``: its debug log off (the request or the frames carry
    secrets)."""
    try:
        uri = parse_uri(url)
    except InvalidURI as exc:
        raise ValueError(f"not a WebSocket URL: {url!r}") from exc
    logger = logging.getLogger("websockets.client")
    return ClientProtocol(
        uri,
        subprotocols=[Subprotocol(s) for s in subprotocols] or None,
        max_size=max_size,
        logger=_NoDebug(logger, {}) if quiet else logger,
    )


def handshake_error(url: str, failure: Exception) -> ConnectError:
    """The error for a handshake websockets refused: :class:`HandshakeRejected`
    for an HTTP status other than 101, else ``ConnectError``."""
    if isinstance(failure, InvalidStatus):
        body = bytes(failure.response.body or b"").decode("utf-8", "replace")
        return HandshakeRejected(failure.response.status_code, body)
    if isinstance(failure, InvalidHandshake):
        return ConnectError(f"WebSocket handshake with {url} failed: {failure}")
    return ConnectError(f"WebSocket handshake with {url} failed: {failure!r}")
