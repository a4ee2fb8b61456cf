"""``connect()``: target parsing, protocol selection, and the client's lifetime."""

from __future__ import annotations

import ipaddress
import re
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Final, Literal

import anyio

from ._core._client import Client
from ._core._connection import Connection
from ._options import ClientOptions
from ._types import DEFAULT_PORTS
from .adapters import (
    Adapter,
    open_foxglove,
    open_rosbridge,
    open_websocket,
    start_foxglove,
    start_rosbridge,
)
from .flow import resolve_presets
from .wire.foxglove import SUBPROTOCOLS

__all__ = ["Endpoint", "connect", "parse_target"]

ProtocolArg = Literal["auto", "foxglove-ws", "rosbridge", "zenoh"]
_PROTOCOLS: Final = ("auto", "foxglove-ws", "rosbridge", "zenoh")
_SCHEMES: Final = {"ws": False, "wss": True, "http": False, "https": True}
_HOSTNAME: Final = re.compile(r"^(?=.{1,253}$)[A-Za-z0-9_](?:[A-Za-z0-9_.-]*[A-Za-z0-9_])?$")


@dataclass(frozen=True, slots=True)
class Endpoint:
    """Where to connect: the parsed form of ``connect()``'s ``target``."""

    host: str
    port: int
    secure: bool
    path: str = "/"
    zenoh: bool = False

    @property
    def url(self) -> str:
        """The WebSocket URL (``ws://`` or ``wss://``), IPv6 hosts bracketed."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'wss' if self.secure else 'ws'}://{host}:{self.port}{self.path}"

    @property
    def zenoh_locator(self) -> str:
        """The zenoh locator (``tcp/host:port``, ``tls/host:port`` when
        secure), IPv6 hosts bracketed."""
        host = f"[{self.host}]" if ":" in self.host else self.host
        return f"{'tls' if self.secure else 'tcp'}/{host}:{self.port}"


def _parse_port(text: str, target: str) -> int:
    if not (text.isascii() and text.isdigit()):
        raise ValueError(f"invalid port {text!r} in target {target!r}")
    port = int(text)
    if not 0 < port < 65536:
        raise ValueError(f"port {port} out of range in target {target!r}")
    return port


def _check_host(host: str, target: str) -> str:
    if not host:
        raise ValueError(f"no host in target {target!r}")
    try:
        return str(ipaddress.ip_address(host))
    except ValueError:
        pass
    if not _HOSTNAME.match(host):
        raise ValueError(f"invalid host {host!r} in target {target!r}")
    # A name whose last label is a number would be read by the resolver as a
    # legacy IPv4 form ("010.1.1.1" is 8.1.1.1): refuse it (WHATWG's rule).
    last = host.rstrip(".").rsplit(".", 1)[-1].lower()
    if last.isdigit() or (last.startswith("0x") and all(c in "0123456789abcdef" for c in last[2:])):
        raise ValueError(f"invalid IPv4 address {host!r} in target {target!r}")
    return host


def parse_target(
    target: str,
    *,
    protocol: str = "auto",
    port: int | None = None,
    secure: bool | None = None,
) -> Endpoint:
    """Parse ``target``: ``host``, ``host:port``, ``[v6]``, ``[v6]:port``, a URL
    (``ws://``, ``wss://``, ``http://``, ``https://``, with an optional path),
    or ``tcp/host:port`` / ``tls/host:port`` (zenoh). An explicit ``port``
    argument wins over the target's; a ``wss://``, ``https://`` or ``tls/``
    scheme implies ``secure=True`` unless ``secure`` is given (over zenoh,
    ``secure=True`` makes a ``tls/`` link). The default port is the protocol's
    (``DEFAULT_PORTS``; ``auto`` uses Foxglove's 8765).

    Raises ``ValueError`` (or ``TypeError``) for anything malformed."""
    if not isinstance(target, str):
        raise TypeError(f"target must be a str, not {type(target).__name__}")
    if protocol not in _PROTOCOLS:
        raise ValueError(f"protocol must be one of {', '.join(_PROTOCOLS)}; got {protocol!r}")
    if port is not None and (isinstance(port, bool) or not isinstance(port, int)):
        raise TypeError("port must be an int or None")
    if port is not None and not 0 < port < 65536:
        raise ValueError(f"port {port} out of range")
    if secure is not None and not isinstance(secure, bool):
        raise TypeError("secure must be a bool or None")
    text = target.strip()
    if not text or any(c.isspace() for c in text):
        raise ValueError(f"invalid target {target!r}")
    scheme_secure: bool | None = None
    path = "/"
    zenoh = False
    if "://" in text:
        scheme, _, rest = text.partition("://")
        scheme = scheme.lower()
        if scheme not in _SCHEMES:
            raise ValueError(f"unsupported scheme {scheme!r} in target {target!r}")
        scheme_secure = _SCHEMES[scheme]
        rest, sep, tail = rest.partition("/")
        path = "/" + tail if sep else "/"
        text = rest
    elif text.lower().startswith(("tcp/", "udp/", "tls/")):
        if text.lower().startswith("udp/"):
            raise ValueError(f"only tcp/ and tls/ zenoh endpoints are supported, got {target!r}")
        scheme_secure = text.lower().startswith("tls/")
        text = text[4:]
        zenoh = True
    if "@" in text:
        raise ValueError(f"credentials in the target are not supported: {target!r}")
    host_text, port_text = text, ""
    if text.startswith("["):
        end = text.find("]")
        if end < 0:
            raise ValueError(f"unclosed '[' in target {target!r}")
        host_text, after = text[1:end], text[end + 1 :]
        if after:
            if not after.startswith(":"):
                raise ValueError(f"unexpected {after!r} after IPv6 address in {target!r}")
            port_text = after[1:]
            if not port_text:
                raise ValueError(f"empty port in target {target!r}")
        try:
            ipaddress.IPv6Address(host_text)
        except ValueError:
            raise ValueError(f"invalid IPv6 address {host_text!r} in {target!r}") from None
    elif text.count(":") == 1:
        host_text, port_text = text.split(":")
        if not port_text:
            raise ValueError(f"empty port in target {target!r}")
    elif text.count(":") > 1:
        raise ValueError(f"IPv6 addresses need brackets: [{text}]:port (target {target!r})")
    host = _check_host(host_text, target)
    if zenoh and protocol not in ("auto", "zenoh"):
        raise ValueError(f"a tcp/ or tls/ endpoint is a zenoh target, but protocol={protocol!r}")
    if protocol == "zenoh" and not zenoh and scheme_secure is not None:
        raise ValueError(
            f"a zenoh target is tcp/host:port, tls/host:port or a host, not a URL: {target!r}"
        )
    zenoh = zenoh or protocol == "zenoh"
    effective = "zenoh" if zenoh else protocol
    default = DEFAULT_PORTS.get(effective, DEFAULT_PORTS["foxglove-ws"])
    chosen = (
        port if port is not None else (_parse_port(port_text, target) if port_text else default)
    )
    is_secure = secure if secure is not None else bool(scheme_secure)
    return Endpoint(host=host, port=chosen, secure=is_secure, path=path, zenoh=zenoh)


async def _open_adapter(
    endpoint: Endpoint, protocol: str, options: ClientOptions, previous: Adapter | None = None
) -> Adapter:
    """``previous``: the connection a reconnect replaces (what the Zenoh
    adapter carries over from it: the record of latched samples delivered)."""
    if endpoint.zenoh or protocol == "zenoh":
        from .adapters._zenoh import open_zenoh  # eclipse-zenoh is an optional extra

        return await open_zenoh(endpoint.zenoh_locator, options, previous)
    if protocol == "rosbridge":
        return await open_rosbridge(endpoint.url, options)
    if protocol == "foxglove-ws":
        return await open_foxglove(endpoint.url, options)
    # auto: offer the Foxglove subprotocols; a Foxglove server picks one, a
    # rosbridge server picks none. One handshake decides.
    deadline = anyio.current_time() + options.connect_timeout
    ws = await open_websocket(endpoint.url, options, SUBPROTOCOLS)
    if ws.subprotocol is None:
        return await start_rosbridge(ws, options, deadline)
    return await start_foxglove(ws, options, deadline)


@asynccontextmanager
async def connect(
    target: str,
    *,
    protocol: ProtocolArg = "auto",
    port: int | None = None,
    secure: bool | None = None,
    options: ClientOptions | None = None,
) -> AsyncIterator[Client]:
    """Connect to a robot's bridge; an async context manager yielding a
    :class:`Client`.

    ``target`` is parsed by :func:`parse_target`; bad targets and arguments
    raise ``ValueError`` / ``TypeError`` at once. Connecting raises
    ``ConnectError`` (refused, timeout, TLS, HTTP rejection) or
    ``ProtocolMismatchError`` (the server speaks something else).
    ``protocol="auto"`` offers the Foxglove subprotocols in the handshake:
    a server that picks one is Foxglove, one that picks none is rosbridge.

    Leaving the block, normally, by an exception or by cancellation, runs
    the teardown in a shielded scope bounded by ``options.teardown_timeout``:
    queued control frames are flushed, a zero Twist goes to every velocity
    topic this client published to and to ``options.stop_topics``, delivery
    is confirmed by a round trip, then the socket closes. The teardown cannot
    stop a robot whose network is already gone: the robot needs its own
    ``cmd_vel`` watchdog."""
    if options is None:
        options = ClientOptions()
    elif not isinstance(options, ClientOptions):
        raise TypeError("options must be a ClientOptions")
    endpoint = parse_target(target, protocol=protocol, port=port, secure=secure)
    presets = resolve_presets(options.preset_overrides, options.logger)  # before any I/O
    adapter = await _open_adapter(endpoint, protocol, options)

    async def reopen() -> Adapter:
        # the same endpoint and the protocol the first connection settled on
        return await _open_adapter(endpoint, adapter.protocol, options, conn.adapter)

    conn = Connection(adapter, options, presets, reopen)
    client = Client(conn, options)
    body_error: Exception | None = None
    try:
        async with anyio.create_task_group() as tg:
            conn.start(tg)
            try:
                yield client
            except Exception as exc:  # re-raised below, outside the task group
                body_error = exc
            finally:
                await conn.teardown()
                conn.stop_tasks()
    finally:
        await conn.close_adapter()
    if body_error is not None:
        raise body_error
