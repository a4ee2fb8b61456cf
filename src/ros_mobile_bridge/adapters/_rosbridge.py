"""The rosbridge v2 adapter: the sans-IO rosbridge engine over the WebSocket
transport. Discovery, parameters and the latency probe go through the
bridge's ``/rosapi/*`` services; messages arrive as JSON, CBOR or cbor-raw
(CDR decoded by the per-connection codec registry)."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

import anyio
import anyio.to_thread

from .._errors import (
    ConnectError,
    DecodeError,
    NotConnected,
    NotSupportedError,
    ProtocolMismatchError,
    RosBridgeError,
    SchemaError,
    ServiceError,
)
from .._options import ClientOptions
from .._types import ServerInfo, ServiceInfo, TopicInfo
from ..codec import CodecRegistry, SchemaTooLarge, same_type_name
from ..flow import Decoder, RawFrame, WireMessage
from ..transport import HandshakeRejected, WebSocket
from ..wire import foxglove as fx
from ..wire import rosbridge as rb
from ..wire._limits import truncate_for_log
from ._parameter_events import PARAMETER_EVENTS
from ._rosbridge_actions import RosbridgeActions
from ._rosbridge_calls import RosbridgeCalls
from ._rosbridge_definitions import RosbridgeDefinitions
from ._rosbridge_discovery import RosbridgeDiscovery
from ._rosbridge_parameters import RosbridgeParameters, SentSubscription
from ._rosbridge_serving import RosbridgeServing
from ._seam import EventSink, SubscribeHints, TopicState
from ._shared import (
    Advertisement,
    Advertisements,
    EventSource,
    as_instance,
    check_fits,
    codec_registry,
    open_websocket,
    plain,
    socket_frame,
)

__all__ = ["RosbridgeAdapter", "open_rosbridge", "start_rosbridge"]


_WIRE_SLACK: Final = 0.5
"""The client's deadline for a call runs this long past the forwarded one,
so the server's own timeout answer arrives first."""
COMPRESSIONS: Final = ("cbor", "cbor-raw")
_STRAY_LOGGED: Final = 256
"""Topics never subscribed whose messages are each logged once."""

_ENCODING: Final[Mapping[str, str]] = {
    "json": "json",
    "parsed": "json",
    "cbor": "cbor",
    "cbor-raw": "cdr",
}


def _decode_json(payload: memoryview) -> Any:
    try:
        return rb.decode_json_msg(payload)
    except (ValueError, RecursionError) as exc:
        raise DecodeError(f"invalid JSON publish frame: {exc}") from None


def _decode_cbor(payload: memoryview) -> Any:
    try:
        return rb.decode_cbor_msg(payload)
    except ValueError as exc:
        raise DecodeError(f"invalid CBOR publish frame: {exc}") from None


def _tolerant(convert: Decoder) -> Decoder:
    """``convert``, giving back what it was given when that does not fit."""

    def tolerant(message: Any) -> Any:
        try:
            return convert(message)
        except DecodeError:
            return message

    return tolerant


def _service_of(request: Any) -> str | None:
    """The service type a request instance belongs to (``pkg/srv/Name``
    of a ``pkg/srv/Name_Request``), else None: a call made before discovery
    learnt the service's type still gets its typed answer."""
    own = getattr(type(request), "__ros_type__", "")
    if isinstance(own, str) and "/srv/" in own and own.endswith("_Request"):
        return own.removesuffix("_Request")
    return None


def _is_foxglove_rejection(exc: HandshakeRejected) -> bool:
    """The Foxglove SDK server's answer to a handshake without its
    subprotocols: HTTP 400 naming the missing header."""
    return exc.status == 400 and "sec-websocket-protocol" in exc.body.lower()


async def open_rosbridge(url: str, options: ClientOptions) -> RosbridgeAdapter:
    """Connect to a rosbridge v2 server at ``url`` and learn its graph, all
    within ``options.connect_timeout``.

    Raises ``ProtocolMismatchError`` when the server speaks Foxglove (its
    HTTP 400 for a handshake without the Foxglove subprotocols, or Foxglove
    frames) or answers nothing."""
    deadline = anyio.current_time() + options.connect_timeout
    try:
        ws = await open_websocket(url, options)
    except HandshakeRejected as exc:
        if _is_foxglove_rejection(exc):
            raise ProtocolMismatchError(
                "rosbridge", "foxglove-ws", f"HTTP {exc.status}: {exc.body.strip()}"
            ) from exc
        raise
    return await start_rosbridge(ws, options, deadline)


async def start_rosbridge(
    ws: WebSocket, options: ClientOptions, deadline: float
) -> RosbridgeAdapter:
    """Speak rosbridge on an open WebSocket: send ``options``' ``auth``
    first when set, then discover the graph until ``deadline``. Closes
    ``ws`` on failure. A failing ``auth`` callable raises ``ConnectError``;
    no answer after an ``auth`` raises ``ProtocolMismatchError`` saying a
    refused ``auth`` looks like that."""
    try:
        if ws.subprotocol in fx.SUBPROTOCOLS:
            raise ProtocolMismatchError(
                "rosbridge", "foxglove-ws", f"the server chose subprotocol {ws.subprotocol}"
            )
        auth = options.auth_message()
        if auth is not None:
            # the protocol's rule: auth comes before any other operation
            await ws.send(
                rb.RosbridgeEngine.auth(
                    mac=auth.mac,
                    client=auth.client,
                    dest=auth.dest,
                    rand=auth.rand,
                    t=auth.t,
                    level=auth.level,
                    end=auth.end,
                )
            )
        adapter = RosbridgeAdapter(ws, options)
        try:
            await adapter.bootstrap(deadline)
        except ProtocolMismatchError as exc:
            if auth is None or exc.detected is not None:
                raise
            # the protocol has no answer to auth: a refusal is silence
            raise ProtocolMismatchError(
                "rosbridge",
                None,
                f"{exc.detail}; an auth operation was sent first, and a server that "
                "refuses it (a wrong or expired MAC) may ignore the client just like this",
            ) from exc
    except BaseException:
        await ws.aclose()
        raise
    return adapter


@dataclass(frozen=True, slots=True)
class _WireSub:
    """What was sent to the bridge for one topic."""

    id: str
    type: str | None
    throttle_rate: int
    queue_length: int
    compression: str | None


@dataclass(slots=True)
class _Publisher(Advertisement):
    id: str
    encode: Callable[[Mapping[str, Any]], bytes]
    check: Callable[[Mapping[str, Any]], bytes] | None
    error: str | None = None


class RosbridgeAdapter:
    """One rosbridge v2 connection (see :class:`~.Adapter`). Its parts are
    objects of sibling modules, built here and given what each needs: the
    requests (:class:`RosbridgeCalls`), discovery (also the node list),
    definitions (the type descriptions), serving, parameters and actions."""

    protocol = "rosbridge"
    confirms_delivery = True  # a WebSocket ping / a rosapi call the server answers
    wire_timeout_slack = _WIRE_SLACK
    assets: None = None  # Foxglove's alone
    playback: None = None

    def __init__(self, ws: WebSocket, options: ClientOptions) -> None:
        self._ws = ws
        self._options = options
        self._log: logging.Logger = options.logger
        self._engine = engine = rb.RosbridgeEngine(
            max_message_size=options.max_frame_size,
            fragment_timeout=options.fragment_timeout,
            max_json_depth=options.max_json_depth,
        )
        self.codecs = codecs = codec_registry(options)
        self.server_info = ServerInfo(name="rosbridge", protocol=self.protocol)
        self._events = events = EventSource()
        self._wanted: dict[str, SubscribeHints] = {}
        self._subs: dict[str, _WireSub] = {}
        self._sub_topics: dict[str, str] = {}  # subscribe id -> topic
        self._live: set[str] = set()  # topics we reported active
        self._decoders: dict[tuple[str, str], Decoder | None] = {}
        # type -> its dict -> instance converter
        self._converters: dict[str, Decoder] = {}
        self._unconvertible: set[str] = set()  # types whose definition cannot build one
        # (type, "json" or "cbor") -> parse, then convert
        self._text_decoders: dict[tuple[str, str, bool], Decoder] = {}
        self._stray: set[str] = set()  # topics we were sent but never subscribed
        self._pubs: Advertisements[_Publisher] = Advertisements()
        self._foreign: str | None = None  # why the server looks like Foxglove
        # the parts
        self._calls = calls = RosbridgeCalls(ws, engine, options)
        self._discovery = RosbridgeDiscovery(calls, options, events, self._resync)
        self._definitions = RosbridgeDefinitions(codecs, calls, self._log)
        self._serving = RosbridgeServing(ws, engine, calls, codecs, self._log)
        self._parameters = RosbridgeParameters(
            ws,
            engine,
            calls,
            codecs,
            events,
            options,
            subscriptions=self._subs,
            decoders=self._decoders,
            send_subscribe=self._send_subscribe,
        )
        self._actions = RosbridgeActions(ws, engine, calls, self._definitions, codecs, self._log)

    @property
    def node_list(self) -> RosbridgeDiscovery:
        return self._discovery

    @property
    def parameters(self) -> RosbridgeParameters:
        return self._parameters

    @property
    def actions(self) -> RosbridgeActions:
        return self._actions

    @property
    def serving(self) -> RosbridgeServing:
        return self._serving

    @property
    def descriptions(self) -> RosbridgeDefinitions:
        return self._definitions

    @property
    def topics(self) -> list[TopicInfo]:
        return self._discovery.topics

    @property
    def services(self) -> list[ServiceInfo]:
        return self._discovery.services

    @property
    def bytes_received(self) -> int:
        return self._ws.bytes_received

    @property
    def messages_received(self) -> int:
        return self._ws.messages_received

    # -- connecting ------------------------------------------------------------
    async def bootstrap(self, deadline: float) -> None:
        """The first discovery, with a temporary reader (the client's reader
        starts after ``connect()`` returns). Called once, by
        :func:`start_rosbridge`."""
        lost: list[ConnectError] = []

        async def read() -> None:
            try:
                await self._read(reading=False)
            except ConnectError as exc:
                lost.append(exc)
                self._calls.pending.fail_all(exc)

        failure: RosBridgeError | None = None
        with anyio.move_on_after(max(deadline - anyio.current_time(), 0.0)) as scope:
            async with anyio.create_task_group() as tg:
                tg.start_soon(read)
                try:
                    await self._discovery.discover(first=True)
                except RosBridgeError as exc:  # raised below, outside the task group
                    failure = exc
                tg.cancel_scope.cancel()
        if self._foreign is not None:
            raise ProtocolMismatchError("rosbridge", "foxglove-ws", self._foreign)
        if lost:
            raise lost[0]
        if failure is not None:
            raise failure
        if scope.cancelled_caught:
            raise ProtocolMismatchError(
                "rosbridge",
                None,
                f"no answer to /rosapi/topics within {self._options.connect_timeout:g} s",
            )

    # -- the reader --------------------------------------------------------------
    async def run(self, sink: EventSink) -> None:
        self._events.attach(sink)
        await self._events.deliver()  # what the first discovery found
        error: ConnectError | None = None
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._discovery.poll)
            try:
                await self._read(reading=True)
            except ConnectError as exc:
                error = exc
            tg.cancel_scope.cancel()
        if error is not None:
            raise error

    async def _read(self, *, reading: bool) -> None:
        """The read loop; ``reading`` False for the bootstrap's temporary
        reader, which answers requests only (no subscription exists yet).
        While it reads for the sink, JSON publish frames are taken where
        they are read when they can be (:meth:`_take_inline`)."""
        ws = self._ws
        engine = self._engine
        sink = self._events.sink if reading else None
        if sink is not None:
            ws.handle_inline(self._take_inline)
        try:
            while True:
                first = await ws.receive_raw()
                ready = ws.receive_ready()  # everything the same read brought: one batch
                received_ns = time.time_ns()
                for text, data in (first, *ready) if ready else (first,):
                    if text and sink is not None:
                        topic = engine.publish_topic(data)
                        if topic is not None and topic != PARAMETER_EVENTS:  # no event built
                            self._on_publish(topic, "json", memoryview(data), received_ns)
                            continue
                    batch = engine.receive_text(data) if text else engine.receive_binary(data)
                    for event in batch:
                        if type(event) is rb.Publish:
                            if sink is not None:
                                self._on_event(event, received_ns)
                        else:
                            if (
                                sink is not None and self._events.pending
                            ):  # what came before goes first
                                pending, self._events.pending = self._events.pending, []
                                await sink.deliver(pending)
                            await self._handle(event)
                if sink is not None:  # (self._deliver, inlined on the hot path)
                    pending, self._events.pending = self._events.pending, []
                    await sink.deliver(pending)
        finally:
            if sink is not None:
                ws.handle_inline(None)

    def _take_inline(self, text: bool, data: bytes, start: int, stop: int) -> bool:
        """The WebSocket's inline handler: a plain JSON ``publish`` frame of a
        subscription that already delivers (its topic reported live, JSON
        asked for) goes to the sink as soon as it is read, with no event
        built (on asyncio in the loop's callbacks, with no task step).
        Anything else is left to the reader (False, nothing done): a binary
        frame, a fragment, another op, a topic never subscribed (the reader
        logs it), a message of an earlier compression still in flight,
        ``/parameter_events`` (the parameter watch reads it), and anything
        while events wait for the sink."""
        if not text or self._events.pending:
            return False
        raw = data[start:stop]
        topic = self._engine.publish_topic(raw)
        if topic is None or topic not in self._live or topic == PARAMETER_EVENTS:
            return False
        wire = self._subs.get(topic)
        sink = self._events.sink
        if wire is None or wire.compression is not None or sink is None:
            return False
        schema, hinted = self._type_of(topic, wire)
        frame = RawFrame(
            topic,
            schema,
            "json",
            memoryview(raw),
            None,
            time.time_ns(),
            self._text_decoder(topic, schema, "json", hinted),
        )
        return sink.deliver_now(frame)

    def _type_of(self, topic: str, wire: _WireSub) -> tuple[str, bool]:
        """The type of ``topic``'s messages, and whether it is only the
        user's ``schema=`` hint (the graph does not say yet): the bridge's
        subscription's type, else the graph's, else the hint."""
        schema = wire.type or self._discovery.topic_types.get(topic, "")
        if schema:
            return schema, False
        hints = self._wanted.get(topic)
        hint = hints.schema if hints is not None else None
        return (hint, True) if hint else ("", False)

    def _text_decoder(self, topic: str, schema: str, kind: str, hinted: bool = False) -> Decoder:
        """The decoder of a JSON or CBOR ``publish`` of ``schema``: the
        message parsed, then made an instance of its class where the
        registry defines the type (built once per type and kind). For a
        type that is only the user's hint (``hinted``), a message that does
        not fit it stays the dict it is."""
        decode = self._text_decoders.get((schema, kind, hinted))
        if decode is not None:
            return decode
        parse = _decode_json if kind == "json" else _decode_cbor
        convert = self._converter(topic, schema)
        if convert is None:
            return parse  # asked again next time: a definition may be learnt meanwhile
        if hinted:
            convert = _tolerant(convert)
        decode = self._text_decoders[(schema, kind, hinted)] = lambda p: convert(parse(p))
        return decode

    def _on_event(self, event: rb.Publish, received_ns: int) -> None:
        topic = event.topic
        if topic == PARAMETER_EVENTS and self._parameters.parameter_events_subscribed:
            self._parameters.on_parameter_event(event)  # the watch's, and the user's if any
        self._on_publish(
            topic, event.kind, event.payload, received_ns, event.message, event.log_time_ns
        )

    def _on_publish(
        self,
        topic: str,
        kind: rb.PublishKind,
        payload: memoryview,
        received_ns: int,
        message: Any = None,
        log_time_ns: int | None = None,
    ) -> None:
        """Queue one received message for delivery (a Publish event's fields)."""
        wire = self._subs.get(topic)
        if wire is None:
            if topic == PARAMETER_EVENTS and self._parameters.parameter_events_subscribed:
                return
            if topic not in self._stray and len(self._stray) < _STRAY_LOGGED:
                self._stray.add(topic)  # logged once per topic, for a bounded set
                self._log.warning(
                    "skipped a message on %s, which this client never subscribed",
                    truncate_for_log(topic, 200),
                )
            return
        if kind != wire.compression and kind in COMPRESSIONS:
            return  # still in flight from before a change of compression
        schema, hinted = self._type_of(topic, wire)
        if kind == "cbor-raw":
            try:
                decode: Decoder | None = self._decoders[(topic, kind)]
            except KeyError:  # (CDR: the graph's type only, never the hint alone)
                decode = self._make_decoder(topic, kind, None if hinted else schema or None)
        else:
            # JSON and CBOR become instances of the type's class where the
            # registry defines it; by type, since the type of a topic's
            # messages is learnt and may change while subscribed
            convert = None
            if kind == "parsed":
                convert = self._converters.get(schema) or self._converter(topic, schema)
                if convert is not None and hinted:
                    convert = _tolerant(convert)
            if kind != "parsed":
                decode = self._text_decoder(topic, schema, kind, hinted)
            elif convert is None:
                decode = lambda _payload: message  # noqa: E731
            else:
                decode = lambda _payload: convert(message)  # noqa: E731
        if topic not in self._live:
            self._set_live(topic, True)
        self._events.pending.append(
            RawFrame(
                topic,
                schema,
                _ENCODING[kind],
                payload,
                log_time_ns,
                received_ns,
                decode,
            )
        )

    def _make_decoder(self, topic: str, kind: str, schema: str | None) -> Decoder | None:
        """The CDR decoder of ``topic``'s cbor-raw messages (None: none,
        they are delivered raw), kept until the topic's subscription
        changes."""
        decode: Decoder | None = None
        try:
            if schema is None:
                raise SchemaError("the topic's type is not known")
            decode = self.codecs.decoder(schema, "cdr")
        except SchemaError as exc:
            self._log.warning(
                "%s: no CDR decoder, cbor-raw messages will be delivered raw: %s",
                topic,
                truncate_for_log(str(exc)),
            )
            if isinstance(exc, SchemaTooLarge):
                self._events.reject("schema_too_large", f"{topic}: {exc}")
        self._decoders[(topic, kind)] = decode
        return decode

    def _converter(self, topic: str, schema: str) -> Decoder | None:
        """The dict -> instance converter of ``schema``, kept; None (asked
        again next time: a definition may be learnt meanwhile) when the
        registry has no ROS definition of it, or it is too large."""
        if not schema or schema in self._unconvertible:
            return None
        try:
            convert = self.codecs.dict_converter(schema)
        except SchemaError as exc:
            if len(self._unconvertible) < _STRAY_LOGGED:  # logged once per type, bounded
                self._unconvertible.add(schema)
            self._log.warning("%s: messages stay dicts: %s", topic, truncate_for_log(str(exc)))
            if isinstance(exc, SchemaTooLarge):
                self._events.reject("schema_too_large", f"{topic}: {exc}")
            return None
        if convert is not None:
            self._converters[schema] = convert
        return convert

    async def _handle(self, event: rb.Event) -> None:
        if isinstance(event, rb.ServiceResponse):
            if not self._calls.resolve(event):
                self._log.debug("a service_response nobody waits for (id %r)", event.id)
        elif isinstance(event, rb.ServiceRequest):
            await self._serving.on_request(event)
        elif isinstance(event, rb.ActionFeedback):
            self._actions.on_feedback(event)
        elif isinstance(event, rb.ActionResult):
            self._actions.on_result(event)
        elif isinstance(event, rb.Status):
            self._on_status(event)
        elif isinstance(event, rb.ForeignProtocol):
            self._foreign = event.reason
            self._calls.pending.fail_all(
                ProtocolMismatchError("rosbridge", event.detected, event.reason)
            )
        elif isinstance(event, rb.ProtocolViolation):
            self._events.reject(event.kind, event.reason)

    def _on_status(self, event: rb.Status) -> None:
        key = event.id or ""
        error = event.level == "error"
        if error and (
            self._calls.fail_status(key, event.msg) or self._actions.on_error_status(key, event.msg)
        ):
            return
        for pub in self._pubs.values():
            if pub.id == key and error:
                pub.error = event.msg
                if pub.ready.is_set():  # nobody waits for it (restored unconfirmed)
                    self._log.error("the bridge refused to advertise a topic: %s", event.msg)
                return
        if self._serving.on_status(event):
            return
        topic = self._sub_topics.get(key)
        if topic is not None and error:
            wire = self._subs.get(topic)
            if wire is not None and wire.type is None:
                # no type yet and the graph lacks the topic: discovery will
                # learn the type and subscribe again
                self._log.info("%s is not in the graph yet: %s", topic, truncate_for_log(event.msg))
            else:
                self._log.warning(
                    "the bridge refused the subscription to %s: %s",
                    topic,
                    truncate_for_log(event.msg),
                )
            return
        level = {"error": logging.ERROR, "warning": logging.WARNING}.get(event.level, logging.INFO)
        self._log.log(level, "server status: %s", truncate_for_log(event.msg))

    # -- discovery ---------------------------------------------------------------
    def topic_active(self, topic: str) -> bool:
        return topic in self._live

    def _set_live(self, topic: str, live: bool) -> None:
        if live:
            self._live.add(topic)
        else:
            self._live.discard(topic)
        self._events.emit(TopicState(topic, live))

    # -- subscriptions -----------------------------------------------------------
    def _desired(self, topic: str, hints: SubscribeHints) -> _WireSub:
        """What to send for ``topic``. The type is the graph's. A ``schema=``
        hint is sent only while discovery does not work: the bridge creates
        a ROS subscription of whatever type it is given, so a wrong hint for
        a topic not in the graph yet would stay there beside the real type.
        Without either the type is omitted (the bridge infers it from the
        graph, or refuses until discovery learns it)."""
        discovered = self._discovery.topic_types.get(topic) or None
        schema = discovered or (None if self._discovery.works else hints.schema)
        if discovered and hints.schema and not same_type_name(discovered, hints.schema):
            self._log.warning(
                "%s: subscribed as %s, but the graph has %s; using %s",
                topic,
                hints.schema,
                discovered,
                discovered,
            )
        rate = 0
        if hints.max_hz is not None and hints.max_hz > 0 and math.isfinite(hints.max_hz):
            rate = max(1, int(1000.0 / hints.max_hz))
        current = self._subs.get(topic)
        sub_id = current.id if current is not None else self._calls.next_id(f"subscribe:{topic}")
        return _WireSub(sub_id, schema, rate, 1 if rate else 0, hints.compression)

    async def _resync(self) -> None:
        """Every wanted subscription in line with the graph (after each
        discovery poll)."""
        for topic in list(self._wanted):
            await self._sync(topic)

    async def _sync(self, topic: str) -> None:
        """Bring the bridge's subscription to ``topic`` in line with what the
        client wants and what discovery knows."""
        hints = self._wanted.get(topic)
        if hints is None:
            return
        want = self._desired(topic, hints)
        current = self._subs.get(topic)
        if current == want:
            if topic in self._discovery.topic_types and topic not in self._live:
                self._set_live(topic, True)
            return
        if want.compression == "cbor-raw" and want.type:
            await self._definitions.fetch_definition(want.type)  # once per connection
        if current is not None and (
            (current.type is not None and current.type != want.type)
            or current.compression != want.compression
        ):
            # the server ignores a re-subscribe that conflicts with the first
            await self._ws.send(self._engine.unsubscribe(topic, id=current.id))
        self._subs[topic] = want
        self._sub_topics[want.id] = topic
        self._decoders.pop((topic, "cbor-raw"), None)
        if want.compression == "cbor-raw" and want.type:
            await self._prepare_decoder(topic, want.type)
        await self._send_subscribe(topic, want)
        if topic in self._discovery.topic_types and topic not in self._live:
            self._set_live(topic, True)

    async def _prepare_decoder(self, topic: str, schema: str) -> None:
        """Build the CDR decoder of a cbor-raw subscription ahead of its first
        message, in a worker thread (tens of milliseconds of code generation
        that would otherwise stall the event loop)."""

        def build() -> Decoder | SchemaError:
            try:
                return self.codecs.decoder(schema, "cdr")
            except SchemaError as exc:
                return exc

        built = await anyio.to_thread.run_sync(build)
        wire = self._subs.get(topic)
        if wire is None or wire.type != schema or wire.compression != "cbor-raw":
            return  # changed meanwhile: the first message builds it
        if isinstance(built, SchemaError):
            return  # the first message logs it, as before
        self._decoders[(topic, "cbor-raw")] = built

    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        if hints.compression is not None and hints.compression not in COMPRESSIONS:
            raise ValueError(f"compression must be one of {COMPRESSIONS} or None")
        self._wanted[topic] = hints
        await self._sync(topic)
        self._events.post()

    async def _send_subscribe(self, topic: str, sub: SentSubscription) -> None:
        """The bridge's ``subscribe`` op for ``topic`` as ``sub`` describes it."""
        await self._ws.send(
            self._engine.subscribe(
                topic,
                id=sub.id,
                type=sub.type,
                throttle_rate=sub.throttle_rate,
                queue_length=sub.queue_length,
                compression=sub.compression,
            )
        )

    async def unsubscribe(self, topic: str) -> None:
        self._wanted.pop(topic, None)
        wire = self._subs.pop(topic, None)
        if topic in self._live:
            self._live.discard(topic)
        if wire is not None:
            self._sub_topics.pop(wire.id, None)
            if not self._ws.closed:
                await self._ws.send(self._engine.unsubscribe(topic, id=wire.id))
            if topic == PARAMETER_EVENTS:
                await self._parameters.user_left_parameter_events()

    # -- publishing --------------------------------------------------------------
    async def advertise(
        self,
        topic: str,
        schema: str,
        *,
        latch: bool = False,
        queue_size: int | None = None,
        best_effort: bool = False,
        confirm: bool = True,
    ) -> None:
        if best_effort:
            raise NotSupportedError("rosbridge's advertise has no best-effort publishing")
        if await self._pubs.reuse(topic, schema):
            return
        pub = _Publisher(
            schema,
            anyio.Event(),
            self._calls.next_id(f"advertise:{topic}"),
            self.codecs.encoder(schema, "json"),
            # a known type is checked here (the bridge would only log a bad
            # field, with no id to tell whose publish it was)
            self.codecs.encoder(schema, "cdr") if self.codecs.has_schema(schema) else None,
        )
        self._pubs[topic] = pub
        try:
            start = anyio.current_time()
            await self._ws.send(
                self._engine.advertise(
                    topic, schema, id=pub.id, latch=latch, queue_size=queue_size or 100
                )
            )
            if confirm:
                await self._calls.round_trip()  # a refusal arrives before this answer
            if pub.error is not None:
                raise SchemaError(
                    f"the bridge refused to advertise {topic} as {schema}: {pub.error}"
                )
            settle = self._options.advertise_settle - (anyio.current_time() - start)
            if settle > 0:
                await anyio.sleep(settle)
        except BaseException:
            self._pubs.pop(topic, None)
            raise
        finally:
            pub.ready.set()

    async def unadvertise(self, topic: str) -> None:
        pub = self._pubs.pop(topic, None)
        if pub is not None:
            # rosbridge_server_rs drops a publish sent right before unadvertise
            await self._calls.round_trip()
            await self._ws.send(self._engine.unadvertise(topic, id=pub.id))

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        pub = self._pubs[topic]
        if pub.check is not None:
            pub.check(data)  # DecodeError naming the field
        return self._engine.publish(topic, pub.encode(data))

    # -- services ------------------------------------------------------------------
    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        args = plain(request) if request is not None else {}
        service_type = _service_of(request) or await self._discovery.service_type(name)
        if not service_type:
            return await self._calls.call(name, args, timeout)
        request_type, response_type = CodecRegistry.service_type_names(service_type)
        await self._definitions.fetch_part(request_type)  # once per type and connection
        check_fits(self.codecs, request_type, args)
        values = await self._calls.call(name, args, timeout)
        await self._definitions.fetch_part(response_type)
        try:
            return as_instance(self.codecs, response_type, values)
        except DecodeError as exc:
            raise ServiceError(name, f"the response does not decode: {exc}") from None

    # -- lifecycle -------------------------------------------------------------------
    async def send(self, message: WireMessage) -> None:
        await self._ws.send(socket_frame(message))

    async def confirm_delivery(self) -> None:
        await self._calls.round_trip()

    def fail_pending(self, error: Exception) -> None:
        assert isinstance(error, RosBridgeError)
        self._calls.pending.fail_all(error)
        self._actions.fail_all(error)

    def publishing(self) -> Mapping[str, str]:
        return self._pubs.schemas()

    def advertised(self, topic: str) -> str | None:
        return self._pubs.ready_schema(topic)

    async def keepalive(self) -> None:
        async with anyio.create_task_group() as tg:
            if self._options.latency_probe_interval > 0:
                tg.start_soon(self._probe_latency)
            interval = self._options.keepalive_interval
            if interval > 0:
                await self._ws.keepalive(interval, self._options.keepalive_timeout)
                tg.cancel_scope.cancel()

    async def _probe_latency(self) -> None:
        """Time ``/rosapi/get_time`` every ``latency_probe_interval``; the
        first failure turns the probe off for this connection."""
        interval = self._options.latency_probe_interval
        while True:
            await anyio.sleep(interval)
            start = time.perf_counter()
            try:
                await self._calls.rosapi("/rosapi/get_time")
            except (ServiceError, TimeoutError) as exc:
                self._log.info("latency probe off for this connection: %s", exc)
                return
            except (ConnectError, NotConnected):
                return
            self._options.report_latency((time.perf_counter() - start) * 1000.0)

    @property
    def closed(self) -> bool:
        return self._ws.closed

    async def aclose(self) -> None:
        await self._ws.aclose()
