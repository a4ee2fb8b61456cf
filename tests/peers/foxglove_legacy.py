"""The deprecated pure-Python Foxglove WebSocket server (``foxglove-websocket``),
a second real peer: it speaks only ``foxglove.websocket.v1``, numbers channels
and services from 0, sends schemas inline, and sends message data and
service responses as *fragmented* binary messages (header, then payload).

It is an asyncio server, and the client under test also runs on trio, so
:class:`LegacyServer` runs it in a thread with its own asyncio event loop;
its methods are synchronous and thread-safe (each one waits for the server
loop to finish the operation). What clients do is recorded by a listener."""

from __future__ import annotations

import asyncio
import logging
import threading
import warnings
from collections.abc import Callable, Coroutine, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

with warnings.catch_warnings():
    # foxglove-websocket is built on websockets' legacy (deprecated) server.
    warnings.simplefilter("ignore", DeprecationWarning)
    from foxglove_websocket.server import FoxgloveServer, FoxgloveServerListener

T = TypeVar("T")

LOG = logging.getLogger("legacy_foxglove_server")
"""The server's own log (its default logger prints DEBUG to stderr)."""

ServiceHandler = Callable[[str, bytes], bytes]
"""``handler(encoding, request_payload) -> response_payload``; raising makes
the server answer with a level-2 ``status`` and no response (its behaviour)."""


class _ErrorLog(logging.Handler):
    """Collects the server's ERROR records: an exception in the server while
    handling what the client sent is logged there, never raised."""

    def __init__(self) -> None:
        super().__init__(logging.ERROR)
        self.messages: list[str] = []  # guarded by the handler's own lock

    def emit(self, record: logging.LogRecord) -> None:
        self.messages.append(record.getMessage())  # handle() holds self.lock


@dataclass(frozen=True)
class Received:
    """One message a client published."""

    channel_id: int
    topic: str
    encoding: str
    schema_name: str
    data: bytes


@dataclass(frozen=True)
class ServiceRequest:
    service_id: int
    call_id: int
    encoding: str
    payload: bytes


@dataclass
class Recorder:
    lock: threading.Lock = field(default_factory=threading.Lock)
    client_channels: dict[int, dict[str, Any]] = field(default_factory=dict)
    advertised: list[dict[str, Any]] = field(default_factory=list)
    unadvertised: list[int] = field(default_factory=list)
    messages: list[Received] = field(default_factory=list)
    subscribed: list[int] = field(default_factory=list)
    unsubscribed: list[int] = field(default_factory=list)
    service_requests: list[ServiceRequest] = field(default_factory=list)


class _Listener(FoxgloveServerListener):  # type: ignore[misc]
    def __init__(self, owner: LegacyServer) -> None:
        self.owner = owner
        self.r = owner.recorder

    def on_subscribe(self, server: Any, channel_id: int) -> None:
        with self.r.lock:
            self.r.subscribed.append(channel_id)

    def on_unsubscribe(self, server: Any, channel_id: int) -> None:
        with self.r.lock:
            self.r.unsubscribed.append(channel_id)

    async def on_client_advertise(self, server: Any, channel: Any) -> None:
        with self.r.lock:
            self.r.advertised.append(dict(channel))
            self.r.client_channels[channel["id"]] = dict(channel)

    async def on_client_unadvertise(self, server: Any, channel_id: int) -> None:
        with self.r.lock:
            self.r.unadvertised.append(channel_id)

    async def on_client_message(self, server: Any, channel_id: int, payload: bytes) -> None:
        with self.r.lock:
            ch = self.r.client_channels.get(channel_id, {})
            self.r.messages.append(
                Received(
                    channel_id,
                    ch.get("topic", "?"),
                    ch.get("encoding", "?"),
                    ch.get("schemaName", "?"),
                    bytes(payload),
                )
            )

    async def on_service_request(
        self, server: Any, service_id: int, call_id: int, encoding: str, payload: bytes
    ) -> bytes:
        with self.r.lock:
            self.r.service_requests.append(
                ServiceRequest(service_id, call_id, encoding, bytes(payload))
            )
        handler = self.owner.service_handlers[service_id]
        return handler(encoding, bytes(payload))


class LegacyServer:
    """A running ``foxglove_websocket.server.FoxgloveServer`` on 127.0.0.1 (an
    ephemeral port). Use as a context manager, or :meth:`start` / :meth:`stop`.
    ``url`` is ``ws://127.0.0.1:PORT``."""

    def __init__(
        self,
        *,
        name: str = "rmb-legacy",
        capabilities: Sequence[str] = ("clientPublish", "services"),
        supported_encodings: Sequence[str] | None = ("json", "cdr"),
    ) -> None:
        self.name = name
        self.capabilities = list(capabilities)
        self.supported_encodings = (
            None if supported_encodings is None else list(supported_encodings)
        )
        self.recorder = Recorder()
        self.service_handlers: dict[int, ServiceHandler] = {}
        self._topics: dict[int, str] = {}
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: Any = None
        self._errors = _ErrorLog()
        self.errors_expected = False
        """Set by a test that makes the server fail on purpose."""
        self.port = 0
        self.url = ""

    # -- lifecycle ----------------------------------------------------------
    def start(self) -> LegacyServer:
        LOG.addHandler(self._errors)
        loop = self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._run_loop, name="legacy-foxglove", daemon=True)
        self._thread.start()
        self.port = self._call(self._start())
        self.url = f"ws://127.0.0.1:{self.port}"
        assert loop.is_running()
        return self

    def _run_loop(self) -> None:
        loop = self._loop
        assert loop is not None
        asyncio.set_event_loop(loop)
        try:
            loop.run_forever()
        finally:
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()

    async def _start(self) -> int:
        server = FoxgloveServer(
            "127.0.0.1",
            0,
            self.name,
            capabilities=self.capabilities,
            supported_encodings=self.supported_encodings,
            logger=LOG,
        )
        server.set_listener(_Listener(self))
        # Its handler takes (connection, path), which websockets deprecates
        # with a warning (an error under this test suite): hand websockets a
        # one-argument wrapper instead.
        handle = server._handle_connection

        async def handler(connection: Any) -> None:
            await handle(connection, connection.path)

        server._handle_connection = handler
        server.start()
        opened = await server.wait_opened()
        self._server = server
        return int(opened.sockets[0].getsockname()[1])

    async def _stop(self) -> None:
        server = self._server
        if server is not None:
            server.close()
            await server.wait_closed()
        current = asyncio.current_task()
        rest = [t for t in asyncio.all_tasks() if t is not current]
        for task in rest:
            task.cancel()
        await asyncio.gather(*rest, return_exceptions=True)

    def stop(self) -> None:
        loop, thread = self._loop, self._thread
        if loop is None or thread is None:
            return
        try:
            self._call(self._stop())
        finally:
            loop.call_soon_threadsafe(loop.stop)
            thread.join(5)
            self._loop = self._thread = None
            LOG.removeHandler(self._errors)

    def __enter__(self) -> LegacyServer:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _call(self, coro: Coroutine[Any, Any, T], timeout: float = 5.0) -> T:
        assert self._loop is not None, "the server is not running"
        return asyncio.run_coroutine_threadsafe(coro, self._loop).result(timeout)

    # -- what the server offers --------------------------------------------
    def add_channel(
        self,
        topic: str,
        *,
        encoding: str,
        schema_name: str,
        schema: str,
        schema_encoding: str | None = None,
    ) -> int:
        """Advertise a channel; returns its id (the first is 0). Without
        ``schema_encoding`` the field is left out, as old servers did."""
        channel: dict[str, Any] = {
            "topic": topic,
            "encoding": encoding,
            "schemaName": schema_name,
            "schema": schema,
        }
        if schema_encoding is not None:
            channel["schemaEncoding"] = schema_encoding
        chan_id = int(self._call(self._server.add_channel(channel)))
        self._topics[chan_id] = topic
        return chan_id

    def remove_channel(self, chan_id: int) -> None:
        self._call(self._server.remove_channel(chan_id))

    def send_message(self, chan_id: int, payload: bytes, timestamp: int = 0) -> None:
        """Send ``payload`` to every client subscribed to ``chan_id``."""
        self._call(self._server.send_message(chan_id, timestamp, payload))

    def add_service(self, service: dict[str, Any], handler: ServiceHandler) -> int:
        """Advertise ``service`` (``name``, ``type`` and the nested
        ``request`` / ``response`` or the flat ``requestSchema`` /
        ``responseSchema`` fields, passed through as given); returns its id."""

        async def add() -> int:
            # register the handler before any client can see the service
            sid = int(self._server._next_service_id)
            self.service_handlers[sid] = handler
            got = int(await self._server.add_service(service))
            assert got == sid
            return got

        return self._call(add())

    def send_status(self, level: int, message: str) -> None:
        self._call(self._server.send_status(level, message))

    # -- what clients did ----------------------------------------------------
    def messages(self, topic: str | None = None) -> list[Received]:
        with self.recorder.lock:
            return [m for m in self.recorder.messages if topic is None or m.topic == topic]

    def subscribed(self) -> list[str]:
        """Topics of the channels clients subscribed to (first subscriber each)."""
        with self.recorder.lock:
            return [self._topics.get(c, "?") for c in self.recorder.subscribed]

    def advertised(self) -> list[dict[str, Any]]:
        with self.recorder.lock:
            return list(self.recorder.advertised)

    def errors(self) -> list[str]:
        """What the server logged at ERROR (e.g. a client message it could
        not handle, or an exception in a service handler)."""
        with self._errors.lock:  # type: ignore[union-attr]
            return list(self._errors.messages)

    def service_requests(self) -> list[ServiceRequest]:
        with self.recorder.lock:
            return list(self.recorder.service_requests)
