"""The contract between the :class:`~ros_mobile_bridge.Client` and a transport
backend. A backend is a wire engine plus a transport; it knows no throttling,
no outbox and no teardown policy. A new transport is one new backend plus one
wire engine."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

import anyio

from .._errors import RosBridgeError
from .._options import HTTPX_MISSING, ClientOptions
from .._types import ServerInfo, ServiceInfo, TopicInfo
from ..codec import CodecRegistry, same_type_name
from ..flow import RawFrame, TopicMessage, WireMessage
from ..transport import WebSocket, connect_websocket

__all__ = [
    "Advertisement",
    "Advertisements",
    "Backend",
    "BackendEvents",
    "GoalEvents",
    "ServiceHandler",
    "SubscribeHints",
    "open_websocket",
    "socket_frame",
]


async def open_websocket(
    url: str, options: ClientOptions, subprotocols: tuple[str, ...] = ()
) -> WebSocket:
    """:func:`~ros_mobile_bridge.transport.connect_websocket` to ``url`` with
    the client's options (message size bound, TLS context, connect timeout,
    read coalescing): the one place every WebSocket of a client is opened,
    by either backend and by ``protocol="auto"``. Raises as
    ``connect_websocket`` does.

    The handshake carries ``options.headers``. websockets' debug log (request
    headers, the start of every frame) is off for a connection that carries
    a secret: with ``options.headers`` or ``options.rosbridge_auth`` set (the
    ``auth`` frame would be logged MAC and all). With ``options.http_client``
    the upgrade goes through that ``httpx.AsyncClient`` (the httpx transport,
    imported only then: ``ImportError`` naming the ``[httpx]`` extra when
    httpx is missing), and the returned object is the same
    :class:`~ros_mobile_bridge.transport.WebSocket` either way."""
    if options.http_client is not None:
        try:
            from ..transport._httpx import connect_httpx_websocket
        except ImportError as exc:
            raise ImportError(HTTPX_MISSING) from exc
        return await connect_httpx_websocket(
            url,
            options.http_client,
            subprotocols=subprotocols,
            max_size=options.max_frame_size,
            timeout=options.connect_timeout,
            read_coalesce=options.read_coalesce,
            headers=options.headers,  # type: ignore[arg-type]
        )
    return await connect_websocket(
        url,
        subprotocols=subprotocols,
        max_size=options.max_frame_size,
        ssl_context=options.ssl_context,
        timeout=options.connect_timeout,
        read_coalesce=options.read_coalesce,
        headers=options.headers,  # type: ignore[arg-type]
        quiet=bool(options.headers) or options.rosbridge_auth is not None,
    )


def socket_frame(message: WireMessage) -> str | bytes:
    """``message`` as a WebSocket frame (text or binary). A
    :class:`~ros_mobile_bridge.flow.TopicMessage` is for per-topic
    transports only: ``TypeError`` here."""
    if isinstance(message, TopicMessage):
        raise TypeError("a TopicMessage cannot be sent on a WebSocket")
    return message


@dataclass(frozen=True, slots=True)
class SubscribeHints:
    """What the client knows about a topic subscription that a bridge can use
    to send less (rosbridge ``throttle_rate``), or to pick a type."""

    max_hz: float | None = None
    schema: str | None = None
    compression: str | None = None
    """rosbridge: ``"cbor"`` or ``"cbor-raw"`` (None: JSON). Other backends
    ignore it."""


@dataclass(slots=True)
class Advertisement:
    """What every backend keeps for a topic this client publishes: its type,
    and whether the bridge is ready for it (set once the advertise is done)."""

    schema: str
    ready: anyio.Event

    async def reuse(self, topic: str, schema: str) -> None:
        """Advertising ``topic`` again: fine with the same type (wait until
        ready), ``ValueError`` with another."""
        if not same_type_name(self.schema, schema):
            raise ValueError(
                f"{topic} is advertised as {self.schema}; unadvertise it before publishing {schema}"
            )
        await self.ready.wait()

    @staticmethod
    def ready_schema(ad: Advertisement | None) -> str | None:
        """``ad``'s type once it is ready to publish, else None."""
        return ad.schema if ad is not None and ad.ready.is_set() else None


A = TypeVar("A", bound=Advertisement)


class Advertisements(dict[str, A]):
    """The topics a backend publishes, by name: the same bookkeeping for
    every backend."""

    def schemas(self) -> dict[str, str]:
        """Every published topic's type (``Backend.publishing``)."""
        return {topic: ad.schema for topic, ad in self.items()}

    def ready_schema(self, topic: str) -> str | None:
        """``topic``'s type once it is ready to publish, else None
        (``Backend.advertised``)."""
        return Advertisement.ready_schema(self.get(topic))

    async def reuse(self, topic: str, schema: str) -> bool:
        """True when ``topic`` is advertised already: with the same type,
        once it is ready; ``ValueError`` with another. False when it is not
        advertised."""
        existing = self.get(topic)
        if existing is None:
            return False
        await existing.reuse(topic, schema)
        return True


class GoalEvents(Protocol):
    """Callbacks the backend's reader makes for one action goal. All run in
    the reader task and must not block."""

    def on_feedback(self, values: Any) -> None:
        """A feedback message for the goal."""

    def on_result(self, status: int | None, values: Any, succeeded: bool) -> None:
        """The goal ended: ``status`` is the ``GoalStatus`` code if known."""

    def on_failed(self, reason: str) -> None:
        """The goal is lost (refused by the server, or the connection went)."""


class ServiceHandler(Protocol):
    """Where a backend hands the calls to a service this client serves."""

    async def on_service_request(self, backend: Backend, request_id: str, args: Any) -> None:
        """A call arrived on ``backend`` (runs in the reader task: it may send
        an answer, and must not wait for anything else)."""

    def on_service_failed(self, error: RosBridgeError) -> None:
        """The bridge refused the service after :meth:`Backend.advertise_service`
        returned (a late refusal, or one to an unconfirmed advertisement):
        ``error`` is a ``SchemaError`` or ``ServiceError``. Runs in the reader
        task; must not block."""


class BackendEvents(Protocol):
    """Callbacks the backend's reader makes into the client. All run in the
    reader task and must not block."""

    def on_frame(self, frame: RawFrame) -> None:
        """A message arrived for a subscribed topic."""

    def on_graph(self) -> None:
        """The topic or service list changed."""

    def on_topic_state(self, topic: str, active: bool) -> None:
        """The server now carries (or no longer carries) ``topic`` to us."""

    def on_parameters(self, values: Mapping[str, Any]) -> None:
        """Unsolicited parameter values (a parameter subscription update)."""

    def on_rejected(self, reason: str, detail: str, count: int = 1) -> None:
        """``count`` inbound frames (or parts of one) were skipped or refused
        for the same reason. ``reason`` is a key of ``Client.rejections``
        (``"invalid_utf8"``, ``"malformed"``, ``"json_depth"``,
        ``"schema_too_large"``, ``"channel_limit"``, ``"service_limit"``,
        ``"fragment_limit"``, ...); ``detail`` says what, untruncated (the
        client truncates it to log). One call is one log line, however large
        ``count`` is: a burst of drops is reported once, not once per frame."""

    async def before_inbound(self) -> None:
        """Called before each inbound message is handled: drain control frames."""


class Backend(Protocol):
    """One connection to one bridge. Built connected by the backend's
    ``open_*`` function; closed by :meth:`aclose`."""

    protocol: str
    server_info: ServerInfo
    codecs: CodecRegistry

    @property
    def topics(self) -> list[TopicInfo]: ...

    @property
    def services(self) -> list[ServiceInfo]: ...

    def topic_active(self, topic: str) -> bool:
        """Whether the server currently carries ``topic`` to this client."""

    async def run(self, events: BackendEvents) -> None:
        """The reader loop. Returns when the connection closed cleanly after
        :meth:`aclose`; raises ``ConnectError`` when it was lost."""

    async def send(self, message: WireMessage) -> None:
        """Write one encoded message (the outbox's writer calls this)."""

    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        """Want ``topic``: subscribe now if the server offers it, otherwise as
        soon as it does. Idempotent per topic."""

    async def unsubscribe(self, topic: str) -> None:
        """No local subscriber wants ``topic`` any more."""

    async def advertise(
        self, topic: str, schema: str, *, latch: bool = False, confirm: bool = True
    ) -> None:
        """Make ``topic`` publishable with type ``schema`` (waits for the
        bridge to be ready). A no-op when already advertised with it.
        ``latch``: the bridge keeps the last message for late subscribers
        (``NotSupportedError`` where the protocol cannot). ``confirm=False``:
        do not wait for an answer only the reader could read (a reconnect
        restores advertisements before the new connection's reader runs); a
        refusal is logged when it arrives."""

    async def unadvertise(self, topic: str) -> None: ...

    def publishing(self) -> Mapping[str, str]:
        """Topics this client advertised, with their schema names."""

    def advertised(self, topic: str) -> str | None:
        """The schema ``topic`` is advertised with and ready to publish, or
        None (then :meth:`advertise` first). Never waits."""

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        """Encode ``data`` for the advertised ``topic``. Raises
        ``DecodeError`` for data that does not fit the schema."""

    wire_timeout_slack: float
    """Seconds the client's deadline for a call runs past the ``timeout``
    forwarded to the server (0 when the protocol forwards none)."""

    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        """Call ``name`` and return the decoded response. ``timeout`` is
        forwarded where the protocol carries one; the client owns the
        deadline. Raises ``ServiceError`` on failure."""

    async def advertise_service(
        self, name: str, service_type: str, handler: ServiceHandler, *, confirm: bool = True
    ) -> None:
        """Serve ``name`` (type ``pkg/srv/Name``): calls go to ``handler``.
        With ``confirm``, returns once the server accepted it (this needs the
        reader running) and raises ``SchemaError`` (unknown type) or
        ``ServiceError`` when it refused; without, returns once sent (a
        refusal is logged: restoring after a reconnect, before the new
        connection's reader runs). ``NotSupportedError`` where the protocol
        cannot serve. When it raises after the advertisement may have taken
        effect (sent, neither confirmed nor refused: a timeout, a
        cancellation), calls may still arrive: the caller answers them and
        then calls :meth:`unadvertise_service`."""

    async def unadvertise_service(self, name: str) -> None:
        """Stop serving ``name`` (a no-op when not served)."""

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        """Answer the call ``request_id`` to ``name``: ``values`` is the
        response (``result`` True) or the reason text (False). ``DecodeError``
        when the response does not fit the type. The frame's write is the
        last step and is not cut by cancellation: when this raises, nothing
        was sent; once the write happened, it returns normally."""

    async def send_action_goal(
        self, action: str, action_type: str, goal: Any, events: GoalEvents
    ) -> str:
        """Send a goal; returns its id. ``events`` hears what becomes of it.
        ``NotSupportedError`` where the protocol has no actions."""

    async def cancel_action_goal(self, action: str, goal_id: str) -> None:
        """Ask the server to cancel goal ``goal_id``."""

    async def get_parameters(self, names: Sequence[str]) -> dict[str, Any]: ...

    async def set_parameters(self, values: Mapping[str, Any]) -> dict[str, Any]: ...

    async def subscribe_parameters(self, names: Sequence[str]) -> None: ...

    async def unsubscribe_parameters(self, names: Sequence[str]) -> None: ...

    async def fetch_definition(self, schema: str) -> bool:
        """Whether a definition of message type ``schema`` is known now,
        after asking the server for one if its protocol can (rosbridge:
        ``/rosapi/message_details``; Foxglove sends definitions only with its
        channels, so there it only checks what is known)."""
        ...

    async def confirm_delivery(self) -> None:
        """Return once everything sent so far has reached the server (a
        round trip), so closing now loses nothing."""

    def fail_pending(self, error: Exception) -> None:
        """Fail every pending request with ``error``."""

    async def keepalive(self) -> None:
        """Run the transport's keep-alive until the connection closes."""

    async def aclose(self) -> None:
        """Close the connection (never raises)."""
