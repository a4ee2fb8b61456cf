"""What every adapter shares, written once: opening a WebSocket with the
client's options, the bookkeeping of advertised topics, handing events to the
sink (:class:`EventSource`)."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, TypeVar

import anyio

from .._errors import ActionGoalError, ServiceError
from .._options import HTTPX_MISSING, ClientOptions
from ..codec import CodecRegistry, same_type_name
from ..codec._workspace import interface_paths_for
from ..flow import TopicMessage, WireMessage
from ..interfaces._base import RosMessage
from ..transport import WebSocket, connect_websocket
from ._seam import Event, EventSink, Rejected

__all__ = [
    "Advertisement",
    "Advertisements",
    "EventSource",
    "as_instance",
    "check_fits",
    "check_pending",
    "open_websocket",
    "plain",
    "socket_frame",
]

_KEPT_BEFORE_RUN: Final = 256
"""Events kept while no reader runs yet (a bootstrap's rejections and graph
changes); more are dropped and counted in one :class:`Rejected` event."""


async def open_websocket(
    url: str, options: ClientOptions, subprotocols: tuple[str, ...] = ()
) -> WebSocket:
    """:func:`~ros_mobile_bridge.transport.connect_websocket` to ``url`` with
    the client's options (message size bound, TLS context, connect timeout,
    read coalescing): the one place every WebSocket of a client is opened,
    by either adapter and by ``protocol="auto"``. Raises as
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


@dataclass(slots=True)
class Advertisement:
    """What every adapter keeps for a topic this client publishes: its type,
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
    """The topics an adapter publishes, by name: the same bookkeeping for
    every adapter."""

    def schemas(self) -> dict[str, str]:
        """Every published topic's type (``Adapter.publishing``)."""
        return {topic: ad.schema for topic, ad in self.items()}

    def ready_schema(self, topic: str) -> str | None:
        """``topic``'s type once it is ready to publish, else None
        (``Adapter.advertised``)."""
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


class EventSource:
    """How an adapter hands its events up: one per connection, held by the
    adapter and by each of its parts that emits. Every emitting place calls
    :meth:`emit` (or :meth:`reject`); the reader passes what collected to
    the sink after each inbound message (:meth:`deliver`); a call from
    outside the reader (a subscribe, a discovery poll) passes them on at its
    end (:meth:`post`). Before :meth:`attach` (the bootstrap, before the
    reader runs) they wait, :data:`_KEPT_BEFORE_RUN` at most.

    :attr:`pending` and :attr:`sink` are public for a reader's hot path,
    which appends frames to ``pending`` and hands the list to the sink
    itself (then sets ``pending`` to a new list), as :meth:`deliver` does."""

    __slots__ = ("_dropped_before_run", "pending", "sink")

    def __init__(self) -> None:
        self.sink: EventSink | None = None
        """Where events go once the reader runs (None before)."""
        self.pending: list[Event] = []
        """Events not handed up yet, in order."""
        self._dropped_before_run = 0

    def attach(self, sink: EventSink) -> None:
        """The reader starts: from now on events go to ``sink``."""
        self.sink = sink
        if self._dropped_before_run:
            dropped = self._dropped_before_run
            self.pending.append(
                Rejected(
                    "overflow",
                    f"{dropped} events before the reader started were dropped",
                    dropped,
                )
            )
            self._dropped_before_run = 0

    def emit(self, event: Event) -> None:
        """Queue ``event`` for the next :meth:`deliver` or :meth:`post`."""
        if self.sink is None and len(self.pending) >= _KEPT_BEFORE_RUN:
            self._dropped_before_run += 1
            return
        self.pending.append(event)

    def reject(self, reason: str, detail: str, count: int = 1) -> None:
        """Hand a rejection up (the router counts it over the client's life
        and logs it)."""
        self.emit(Rejected(reason, detail, count))

    async def deliver(self) -> None:
        """The reader's turn: hand what collected to the sink (even nothing:
        the sink writes queued control frames before the next message)."""
        sink = self.sink
        if sink is not None:
            pending, self.pending = self.pending, []
            await sink.deliver(pending)

    def post(self) -> None:
        """Outside the reader: hand what collected to the sink at once."""
        sink = self.sink
        if sink is not None and self.pending:
            pending, self.pending = self.pending, []
            for event in pending:
                sink.post(event)


def codec_registry(options: ClientOptions) -> CodecRegistry:
    """A connection's :class:`CodecRegistry`: the options' schema bounds, and
    their local interface paths (plus ``$AMENT_PREFIX_PATH`` unless turned
    off), scanned once per process for each distinct list."""
    return CodecRegistry(
        max_schema_size=options.max_schema_size,
        max_schema_fields=options.max_schema_fields,
        interfaces=interface_paths_for(
            options.interface_paths, ament_prefix_path=options.ament_prefix_path
        ),
    )


def check_fits(codecs: CodecRegistry, type_name: str, data: Mapping[str, Any]) -> None:
    """Raise :class:`~ros_mobile_bridge.MessageError` naming the field when
    ``data`` does not fit ``type_name``, where its definition is known; do
    nothing when it is not. For a transport that sends the caller's dict as
    it is (rosbridge's JSON): the bridge would answer a misfit with its own
    words, or only log it, so the same mistake raises the same class as on
    the transports that encode here."""
    if codecs.has_schema(type_name):
        codecs.encoder(type_name, "cdr")(data)


def plain(value: Any) -> Any:
    """``value`` as the plain data a JSON bridge takes: a message instance
    becomes its dict (:meth:`~ros_mobile_bridge.interfaces.RosMessage.to_dict`),
    numpy arrays (in it, or given) lists, mappings and lists new ones;
    anything else is returned as it is."""
    if isinstance(value, RosMessage):
        value = value.to_dict()
    if isinstance(value, Mapping):
        return {k: plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    tolist = getattr(value, "tolist", None)
    if tolist is not None and not isinstance(value, str | bytes | int | float | bool):
        return tolist()
    return value


def as_instance(codecs: CodecRegistry, type_name: str | None, values: Any) -> Any:
    """A JSON bridge's message ``values`` (nested dicts) as an instance of
    ``type_name``'s class where the registry has its ROS definition, else
    ``values`` as they are. Raises :class:`~ros_mobile_bridge.DecodeError`
    naming the field when they do not fit the definition."""
    if not type_name or not isinstance(values, Mapping):
        return values
    convert = codecs.dict_converter(type_name)
    return values if convert is None else convert(values)


def check_pending(
    options: ClientOptions,
    waiting: int,
    what: str,
    error: type[ServiceError] | type[ActionGoalError] = ServiceError,
) -> None:
    """Raise ``error`` naming ``what`` at once when ``waiting`` requests
    (calls, goals, parameter requests) already wait for an answer on a
    connection and that reaches ``options.max_pending_requests``: the one
    bound, and its one message, for every adapter."""
    limit = options.max_pending_requests
    if waiting >= limit:
        raise error(what, f"{limit} requests already wait for an answer (max_pending_requests)")
