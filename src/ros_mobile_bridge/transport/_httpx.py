"""The WebSocket opened through a caller's ``httpx.AsyncClient``.

httpx makes the HTTP upgrade (so the client's proxies, auth, cookies, default
headers, TLS settings and custom transport all apply), then the library's own
:class:`~ros_mobile_bridge.transport.WebSocket` runs on the upgraded
connection: the same reader, fast path, size bound, keep-alive and closing
rules as the default transport, one code path for the adapters.

The request is the one websockets' sans-IO client builds (key, version,
subprotocols), sent by httpx; httpx's answer is fed back to that client as
bytes, so it checks ``Sec-WebSocket-Accept`` and the chosen subprotocol
exactly as on the default path.

httpx and httpcore are imported only when this module is, and this module
only when :attr:`~ros_mobile_bridge.ClientOptions.http_client` is set."""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from typing import Any, Final

import anyio
import anyio.abc
import httpcore
import httpx
from websockets.http11 import Response

from .._errors import ConnectError
from ._websocket import WebSocket
from ._ws_connect import HandshakeRejected, client_protocol, handshake_error

__all__ = ["HttpxByteStream", "connect_httpx_websocket"]

_BODY_LIMIT: Final = 4096
"""Bytes of a refusal's body kept for :class:`HandshakeRejected`."""


class HttpxByteStream(anyio.abc.ByteStream):
    """An anyio byte stream over the network stream httpx hands over after a
    ``101 Switching Protocols`` (``response.extensions["network_stream"]``).
    Closing it closes that stream, then the httpx response (which returns
    the connection to nobody: an upgraded connection is never reused)."""

    def __init__(self, network: Any, response: httpx.Response) -> None:
        self._network = network
        self._response = response
        self._closed = False

    async def receive(self, max_bytes: int = 65536) -> bytes:
        if self._closed:
            raise anyio.ClosedResourceError
        try:
            data: bytes = await self._network.read(max_bytes)
        except (httpcore.NetworkError, httpcore.TimeoutException, OSError) as exc:
            raise anyio.BrokenResourceError(str(exc) or type(exc).__name__) from exc
        if not data:
            raise anyio.EndOfStream
        return data

    async def send(self, item: bytes) -> None:
        if self._closed:
            raise anyio.ClosedResourceError
        try:
            await self._network.write(item)
        except (httpcore.NetworkError, httpcore.TimeoutException, OSError) as exc:
            raise anyio.BrokenResourceError(str(exc) or type(exc).__name__) from exc

    async def send_eof(self) -> None:
        """A network stream cannot half-close: the whole stream closes."""
        await self.aclose()

    async def aclose(self) -> None:
        if self._closed:
            return
        self._closed = True
        with anyio.CancelScope(shield=True), anyio.move_on_after(1.0):
            with contextlib.suppress(httpcore.NetworkError, OSError):
                await self._network.aclose()
            with contextlib.suppress(httpx.HTTPError, httpcore.NetworkError, OSError):
                await self._response.aclose()


def _http_url(url: str) -> str:
    """``ws://``/``wss://`` as the ``http://``/``https://`` httpx requests."""
    if url.startswith("ws://"):
        return "http://" + url[5:]
    if url.startswith("wss://"):
        return "https://" + url[6:]
    raise ValueError(f"not a WebSocket URL: {url!r}")


async def _refusal_body(response: httpx.Response) -> str:
    body = bytearray()
    try:
        async for chunk in response.aiter_raw():
            body += chunk
            if len(body) >= _BODY_LIMIT:
                break
    except httpx.HTTPError:
        pass
    return bytes(body[:_BODY_LIMIT]).decode("utf-8", "replace")


async def connect_httpx_websocket(
    url: str,
    client: httpx.AsyncClient,
    *,
    subprotocols: tuple[str, ...] = (),
    max_size: int | None = 1 << 20,
    timeout: float = 10.0,
    read_coalesce: float = 0.0,
    headers: Sequence[tuple[str, str]] = (),
) -> WebSocket:
    """Open a WebSocket to ``url`` through ``client``; otherwise as
    :func:`~ros_mobile_bridge.transport.connect_websocket` (same errors:
    :class:`HandshakeRejected` for an HTTP status other than 101,
    ``ConnectError`` for a refused connection, a proxy or TLS failure, a
    timeout, an HTTP/2 answer, or a client transport that cannot upgrade a
    connection (no network stream after the 101), ``ValueError`` for a bad
    URL). ``timeout`` bounds the whole upgrade on top of the client's own
    timeouts."""
    proto = client_protocol(url, subprotocols, max_size, quiet=True)
    request = proto.connect()
    for name, value in headers:
        request.headers[name] = value
    sent = [(k, v) for k, v in request.headers.raw_items() if k.lower() != "host"]
    http_request = client.build_request("GET", _http_url(url), headers=sent)
    response: httpx.Response | None = None
    try:
        with anyio.fail_after(timeout):
            response = await client.send(http_request, stream=True)
            # the version first: an HTTP/2 answer (no 101 exists there) is
            # the client's http2=True, not a refusal
            if response.http_version != "HTTP/1.1":
                raise ConnectError(
                    f"WebSocket upgrade to {url} answered over {response.http_version}: "
                    "use an httpx.AsyncClient without http2"
                )
            if response.status_code != 101:
                body = await _refusal_body(response)
                raise HandshakeRejected(response.status_code, body)
            network = response.extensions.get("network_stream")
            if network is None:
                raise ConnectError(
                    f"WebSocket upgrade to {url}: the httpx client's transport answered 101 "
                    "but handed over no network stream (response.extensions"
                    "['network_stream']): it cannot upgrade a connection (httpx.MockTransport "
                    "and ASGITransport cannot; use httpx's default transport)"
                )
    except TimeoutError as exc:
        await _close(response)
        raise ConnectError(f"timed out after {timeout:g} s connecting to {url}") from exc
    except httpx.HTTPError as exc:
        await _close(response)
        raise ConnectError(f"cannot connect to {url}: {_describe(exc)}") from exc
    except BaseException:
        await _close(response)
        raise
    raw = bytearray(f"HTTP/1.1 101 {response.reason_phrase or 'Switching Protocols'}\r\n".encode())
    for raw_name, raw_value in response.headers.raw:
        raw += raw_name + b": " + raw_value + b"\r\n"
    raw += b"\r\n"
    proto.receive_data(bytes(raw))
    events = proto.events_received()
    stream = HttpxByteStream(network, response)
    if proto.handshake_exc is not None or not any(isinstance(e, Response) for e in events):
        await stream.aclose()
        failure = proto.handshake_exc or RuntimeError("no handshake response")
        raise handshake_error(url, failure) from failure
    ws = WebSocket(stream, proto, max_size)
    ws.read_coalesce = read_coalesce
    return ws


def _describe(exc: BaseException) -> str:
    """``exc`` in words: its own text, or (httpx's trio backend raises
    errors with none) the first cause or context that has some."""
    seen: BaseException | None = exc
    for _ in range(8):
        if seen is None:
            break
        if str(seen):
            return f"{type(seen).__name__}: {seen}"
        seen = seen.__cause__ or seen.__context__
    return repr(exc)


async def _close(response: httpx.Response | None) -> None:
    if response is None:
        return
    with (
        anyio.CancelScope(shield=True),
        anyio.move_on_after(1.0),
        contextlib.suppress(httpx.HTTPError, OSError),
    ):
        await response.aclose()
