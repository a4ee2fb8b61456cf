"""The Foxglove WebSocket adapter: the sans-IO Foxglove engine over the
WebSocket transport, with schemas decoded by the per-connection codec
registry."""

from __future__ import annotations

import bisect
import itertools
import logging
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Final

import anyio
import anyio.to_thread

from .._errors import (
    ConnectError,
    DecodeError,
    NotSupportedError,
    ProtocolMismatchError,
    RosBridgeError,
    SchemaError,
    ServiceError,
    connection_lost,
)
from .._options import ClientOptions
from .._types import ServerInfo, ServerStatus, ServiceInfo, StatusLevel, StatusRemoved, TopicInfo
from ..codec import CodecRegistry, SchemaTooLarge
from ..flow import Decoder, PendingRequests, RawFrame, WireMessage
from ..interfaces._base import RosMessage
from ..transport import WebSocket
from ..wire import foxglove as fx
from ..wire._limits import truncate_for_log
from ._foxglove_offers import FoxgloveAssets, FoxgloveGraph, FoxglovePlayback
from ._foxglove_parameters import FoxgloveParameters
from ._pauses import PauseSchedule
from ._seam import (
    EventSink,
    GraphChanged,
    ParameterValues,
    Replayed,
    ServerClock,
    SubscribeHints,
    TopicState,
)
from ._shared import (
    Advertisement,
    Advertisements,
    EventSource,
    check_pending,
    codec_registry,
    open_websocket,
    socket_frame,
)

__all__ = ["FoxgloveAdapter", "open_foxglove", "start_foxglove"]

_EMPTY_CDR: Final = b"\x00\x01\x00\x00"
_LEVELS: Final[dict[int, tuple[StatusLevel, int]]] = {
    0: ("info", logging.INFO),
    1: ("warning", logging.WARNING),
    2: ("error", logging.ERROR),
}
"""A status ``level`` -> its name and log level (an unknown level is an error)."""
_STATUS_IDS_KEPT: Final = 1024
"""Status ids whose message is kept for the log line of their withdrawal."""
"""A CDR encapsulation header (little endian) with no body: an empty request."""


@dataclass(slots=True)
class _ClientChannel(Advertisement):
    id: int
    topic: str
    encoding: str
    encode: Any


async def open_foxglove(url: str, options: ClientOptions) -> FoxgloveAdapter:
    """Connect to a Foxglove WebSocket server at ``url`` and wait for its
    ``serverInfo``, all within ``options.connect_timeout``.

    Raises ``ProtocolMismatchError`` when the server does not speak Foxglove
    (it picked none of the subprotocols, or never sent ``serverInfo``)."""
    deadline = anyio.current_time() + options.connect_timeout
    ws = await open_websocket(url, options, fx.SUBPROTOCOLS)
    return await start_foxglove(ws, options, deadline)


async def start_foxglove(ws: WebSocket, options: ClientOptions, deadline: float) -> FoxgloveAdapter:
    """Speak Foxglove on an open WebSocket (opened offering
    :data:`~ros_mobile_bridge.wire.foxglove.SUBPROTOCOLS`): wait for
    ``serverInfo`` and the first advertisements until ``deadline``. Closes
    ``ws`` on failure."""
    try:
        if ws.subprotocol is None:
            raise ProtocolMismatchError(
                "foxglove-ws", "rosbridge", "the server accepted none of the Foxglove subprotocols"
            )
        engine = fx.FoxgloveEngine(
            ws.subprotocol,
            max_channels=options.max_channels,
            max_services=options.max_services,
            max_schema_size=options.max_schema_size,
            max_json_depth=options.max_json_depth,
        )
        early: list[fx.Event] = []
        with anyio.move_on_after(max(deadline - anyio.current_time(), 0.0)):
            while not _greeted(engine):
                text, data = await ws.receive_raw()
                events = engine.receive_text(data) if text else engine.receive_binary(data)
                # the greeting itself is not replayed to the reader
                early.extend(e for e in events if not isinstance(e, fx.ServerInfo))
        if not _greeted(engine):
            raise ProtocolMismatchError(
                "foxglove-ws",
                None,
                f"no serverInfo within {options.connect_timeout:g} s of connecting",
            )
        # The first advertisements follow serverInfo at once; a server with no
        # channels sends none, so wait only a short grace for them.
        info = engine.server_info
        assert info is not None
        want_services = "services" in info.capabilities
        seen_channels = seen_services = False
        grace = min(options.discovery_grace, max(deadline - anyio.current_time(), 0.0))
        with anyio.move_on_after(grace):
            while not (seen_channels and (seen_services or not want_services)):
                text, data = await ws.receive_raw()
                events = engine.receive_text(data) if text else engine.receive_binary(data)
                early.extend(events)
                seen_channels |= any(isinstance(e, fx.Advertise) for e in events)
                seen_services |= any(isinstance(e, fx.AdvertiseServices) for e in events)
    except BaseException:
        await ws.aclose()
        raise
    return FoxgloveAdapter(ws, engine, options, early)


def _greeted(engine: fx.FoxgloveEngine) -> bool:
    return engine.server_info is not None


class FoxgloveAdapter:
    """One Foxglove WebSocket connection (see :class:`~.Adapter`). Its
    optional parts: :attr:`parameters`, when the server offers them;
    :attr:`assets`, :attr:`node_list` (the connection graph) and
    :attr:`playback`, which check the server's capability per call. The protocol has no actions,
    no type descriptions, and a client cannot serve a service over it."""

    protocol = "foxglove-ws"
    confirms_delivery = True  # a WebSocket ping / a rosapi call the server answers
    wire_timeout_slack = 0.0  # the protocol carries no timeout
    actions: None = None
    serving: None = None
    descriptions: None = None

    def __init__(
        self,
        ws: WebSocket,
        engine: fx.FoxgloveEngine,
        options: ClientOptions,
        early_events: list[fx.Event],
    ) -> None:
        self._ws = ws
        self._engine = engine
        self._options = options
        self._log: logging.Logger = options.logger
        self.codecs = codec_registry(options)
        # channel id -> (the channel it was built for, its decoder)
        self._decoders: dict[int, tuple[fx.Channel, Decoder | None]] = {}
        # topic -> its channels, oldest first; the sorted topic list follows it
        self._by_topic: dict[str, dict[int, fx.Channel]] = {}
        self._indexed: dict[int, fx.Channel] = {}
        self._building: dict[int, tuple[fx.Channel, anyio.Event]] = {}
        self._topic_names: list[str] = []
        self._topic_infos: list[TopicInfo] = []
        self._wanted: dict[str, SubscribeHints] = {}
        self._active: dict[str, int] = {}  # topic -> subscription id
        # save_bandwidth (SubscribeHints.pause_hz): a paused topic keeps the
        # channel it paused on; the first message after a resumption may be
        # the server's replay (foxglove_bridge, transient-local topics)
        self._pauses: PauseSchedule[fx.Channel] = PauseSchedule()
        self._pubs: Advertisements[_ClientChannel] = Advertisements()
        self._calls: PendingRequests[Any] = PendingRequests()
        self._call_ids = itertools.count(1)
        self._events = EventSource()
        self._early = early_events
        info = engine.server_info
        assert info is not None
        self.server_info = self._server_info(info)
        self._parameters = FoxgloveParameters(
            engine,
            send_request=self._send_request,
            send=ws.send,
            check_pending=self._check_pending,
            capabilities=lambda: self.server_info.capabilities,
            closed=lambda: ws.closed,
        )
        self._params = self._parameters.requests
        capabilities = self._capabilities
        self.assets = FoxgloveAssets(engine, self._send_request, self._check_pending, capabilities)
        self.node_list = FoxgloveGraph(
            engine, self._send_request, capabilities, options, self._events.reject
        )
        self.playback = FoxglovePlayback(
            engine, self._send_request, self._check_pending, capabilities
        )
        self._statuses: dict[str, tuple[str, int]] = {}  # status id -> (message, log level)
        self.parameters: FoxgloveParameters | None = None
        self._offer_parameters()
        self._index_channels(tuple(engine.channels.values()), ())

    def _capabilities(self) -> tuple[str, ...]:
        """The server's capabilities now (a later serverInfo may change them)."""
        return self.server_info.capabilities

    def _offer_parameters(self) -> None:
        """:attr:`parameters` as the server's capabilities say now."""
        offered = "parameters" in self.server_info.capabilities
        self.parameters = self._parameters if offered else None

    def _server_info(self, info: fx.ServerInfo) -> ServerInfo:
        return ServerInfo(
            name=info.name,
            protocol=self.protocol,
            subprotocol=self._engine.subprotocol,
            capabilities=info.capabilities,
            supported_encodings=info.supported_encodings,
            metadata=dict(info.metadata),
            session_id=info.session_id,
        )

    # -- discovery ----------------------------------------------------------
    @property
    def topics(self) -> list[TopicInfo]:
        """Sorted by name; kept up to date per advertisement (the cost of one
        is that of the channels it names, plus one list copy here)."""
        return list(self._topic_infos)

    @property
    def services(self) -> list[ServiceInfo]:
        return sorted(
            (ServiceInfo(s.name, s.type) for s in self._engine.services.values()),
            key=lambda s: s.name,
        )

    def topic_active(self, topic: str) -> bool:
        return topic in self._active or topic in self._pauses.paused

    def _graph(self) -> GraphChanged:
        return GraphChanged(self.topics, self.services)

    def _index_channels(self, added: Sequence[fx.Channel], removed: Sequence[fx.Channel]) -> None:
        """Follow an advertisement in the topic index and the sorted topic
        list: work for the channels named, not for all of them."""
        touched: set[str] = set()
        indexed = self._indexed
        for ch in (*removed, *added):
            old = indexed.pop(ch.id, None)  # gone, or re-advertised (maybe as another topic)
            if old is not None:
                self._by_topic.get(old.topic, {}).pop(ch.id, None)
                touched.add(old.topic)
        for ch in added:
            indexed[ch.id] = ch
            self._by_topic.setdefault(ch.topic, {})[ch.id] = ch
            touched.add(ch.topic)
        names, infos = self._topic_names, self._topic_infos
        for topic in touched:
            channels = self._by_topic.get(topic)
            i = bisect.bisect_left(names, topic)
            present = i < len(names) and names[i] == topic
            if not channels:
                self._by_topic.pop(topic, None)
                if present:
                    del names[i]
                    del infos[i]
                continue
            first = next(iter(channels.values()))
            info = TopicInfo(topic, first.schema_name, first.encoding)
            if present:
                infos[i] = info
            else:
                names.insert(i, topic)
                infos.insert(i, info)

    def _channel_for(self, topic: str) -> fx.Channel | None:
        best: fx.Channel | None = None
        for ch in self._by_topic.get(topic, {}).values():
            if best is None or ch.encoding == "cdr":
                best = ch
        return best

    def _service_for(self, name: str) -> fx.ServiceDef | None:
        for svc in self._engine.services.values():
            if svc.name == name:
                return svc
        return None

    # -- the reader ---------------------------------------------------------
    async def run(self, sink: EventSink) -> None:
        """The reader, and beside it the task that resumes paused topics
        (``save_bandwidth``); both end with the connection."""
        error: ConnectError | None = None
        async with anyio.create_task_group() as tg:
            tg.start_soon(self._resume_paused)
            try:
                await self._read(sink)
            except ConnectError as exc:
                error = exc
            tg.cancel_scope.cancel()
        if error is not None:
            raise error

    async def _read(self, sink: EventSink) -> None:
        self._events.attach(sink)
        early, self._early = self._early, []
        for event in early:
            await self._handle(event)
        await self._events.deliver()
        ws = self._ws
        engine = self._engine
        saving = self._pauses.rates  # (updated in place)
        ws.handle_inline(self._take_inline)
        ws.hold_reads(self._quiet_until)
        try:
            while True:
                text, message = await ws.receive_raw()
                if text:  # UTF-8 bytes: the engine reports invalid ones
                    for event in engine.receive_text(message):
                        await self._handle(event)
                    await self._events.deliver()
                    continue
                received_ns = time.time_ns()
                pending = self._events.pending
                for event in engine.receive_binary(message):
                    if type(event) is fx.MessageData:
                        if saving and event.channel.topic in saving:
                            await self._saved_frame(event, received_ns)
                            pending = self._events.pending  # (a subscribe call may have posted)
                        else:
                            pending.append(self._frame(event, received_ns))
                    else:
                        await self._handle(event)
                        pending = self._events.pending
                self._events.pending = []
                await sink.deliver(pending)  # (self._deliver, inlined on the hot path)
        finally:
            ws.handle_inline(None)
            ws.hold_reads(None)

    def _take_inline(self, text: bool, data: bytes, start: int, stop: int) -> bool:
        """The WebSocket's inline handler: a message-data frame of a live
        subscription whose decoder is built goes to the sink as soon as it is
        read (on asyncio in the loop's read callback, with no task step),
        with no event or event list built. Anything else, anything while
        events wait for the sink, and a topic in bandwidth mode (its pause
        is the reader's) is left to the reader (False), unchanged."""
        if text or self._events.pending:
            return False
        peeked = self._engine.peek_message_data(data, start, stop)
        if peeked is None:
            return False
        channel, log_time_ns, payload = peeked
        entry = self._decoders.get(channel.id)
        sink = self._events.sink
        if entry is None or entry[0] is not channel or sink is None:
            return False  # the reader builds the decoder
        saving = self._pauses.rates
        if saving and channel.topic in saving:
            return False
        frame = RawFrame(
            channel.topic,
            channel.schema_name,
            channel.encoding,
            payload,
            log_time_ns,
            time.time_ns(),
            entry[1],
        )
        return sink.deliver_now(frame)

    def _quiet_until(self, now: float) -> float:
        """The WebSocket's :meth:`~WebSocket.hold_reads` callable: the sink's
        :meth:`~EventSink.quiet_until`, unless a request waits for its answer
        or a topic saves bandwidth (its pauses are timed by the reader)."""
        sink = self._events.sink
        if (
            sink is None
            or self._calls
            or self._params
            or self.assets.requests
            or self.playback.requests
            or self._pauses.rates
        ):
            return 0.0
        return sink.quiet_until(now)

    async def _send_request(self, message: bytes | str) -> None:
        """Send a request whose answer must be read as it comes: a hold of
        the reads ends first (see :meth:`_quiet_until`)."""
        self._ws.end_hold()
        await self._ws.send(message)

    def _frame(self, event: fx.MessageData, received_ns: int) -> RawFrame:
        channel = event.channel
        entry = self._decoders.get(channel.id)
        if entry is not None and entry[0] is channel:
            decode = entry[1]
        else:  # not built ahead (a channel re-advertised meanwhile): build it here
            decode = self._store_decoder(channel, self._build_decoder(channel))
        return RawFrame(
            channel.topic,
            channel.schema_name,
            channel.encoding,
            event.payload,
            event.log_time_ns,
            received_ns,
            decode,
        )

    def _build_decoder(self, channel: fx.Channel) -> Decoder | SchemaError:
        """Parse the channel's schema and build its decoder (thread-safe: the
        registry locks). The error instead when there is none."""
        try:
            if channel.schema and channel.schema_encoding:
                self.codecs.add_schema(channel.schema_name, channel.schema_encoding, channel.schema)
            return self.codecs.decoder(channel.schema_name, channel.encoding)
        except SchemaError as exc:
            return exc

    def _store_decoder(self, channel: fx.Channel, built: Decoder | SchemaError) -> Decoder | None:
        decode: Decoder | None = None
        if isinstance(built, SchemaError):
            what = f"channel {channel.id} ({channel.topic}, {channel.schema_name})"
            if isinstance(built, SchemaTooLarge):
                self._events.reject("schema_too_large", f"{what}: {built}")
            else:
                self._log.warning(
                    "%s: no decoder, messages will be delivered raw: %s",
                    truncate_for_log(what),
                    truncate_for_log(str(built)),
                )
        else:
            decode = built
        self._decoders[channel.id] = (channel, decode)
        return decode

    async def _prepare_decoder(self, channel: fx.Channel) -> None:
        """Build the channel's decoder ahead of its first message, in a
        worker thread: parsing a schema and generating its code can take tens
        of milliseconds that would otherwise stall the event loop (and read
        as lag to the adaptive throttle). JSON needs nothing built."""
        entry = self._decoders.get(channel.id)
        if entry is not None and entry[0] is channel:
            return
        if channel.encoding.strip().lower() == "json":
            self._store_decoder(channel, self._build_decoder(channel))
            return
        building = self._building.get(channel.id)
        if building is not None and building[0] is channel:
            await building[1].wait()  # the reader and a subscriber at once: build once
            return
        done = anyio.Event()
        self._building[channel.id] = (channel, done)
        try:
            built = await anyio.to_thread.run_sync(self._build_decoder, channel)
            if self._engine.channels.get(channel.id) is channel:  # still current
                self._store_decoder(channel, built)
        finally:
            if self._building.get(channel.id, (None,))[0] is channel:
                del self._building[channel.id]
            done.set()

    async def _handle(self, event: fx.Event) -> None:
        """Follow one engine event; what the layer above must hear goes to
        :meth:`_emit`."""
        if isinstance(event, fx.Advertise):
            for ch in event.channels:
                entry = self._decoders.get(ch.id)
                if entry is not None and entry[0] is not ch:
                    del self._decoders[ch.id]  # a re-used id gets a fresh decoder
            self._index_channels(event.channels, ())
            for ch in event.channels:
                topic = ch.topic
                if (
                    topic in self._wanted
                    and topic not in self._active
                    and topic not in self._pauses.paused
                ):
                    await self._subscribe_channel(ch)
            self._events.emit(self._graph())
        elif isinstance(event, fx.Unadvertise):
            self._index_channels((), event.channels)
            for ch in event.channels:
                sub_id = self._active.get(ch.topic)
                paused = self._pauses.paused.get(ch.topic)
                if paused is not None and paused[1] == ch:
                    self._pauses.unpause(ch.topic)  # resubscribed below if another carries it
                    self._events.emit(TopicState(ch.topic, False))
                    other = self._channel_for(ch.topic)
                    if other is not None and ch.topic in self._wanted:
                        await self._subscribe_channel(other)
                elif sub_id is not None and self._engine.subscription_channel(sub_id) == ch:
                    del self._active[ch.topic]
                    self._events.emit(TopicState(ch.topic, False))
                    # another channel may still carry the topic
                    other = self._channel_for(ch.topic)
                    if other is not None and ch.topic in self._wanted:
                        await self._subscribe_channel(other)
            self._events.emit(self._graph())
        elif isinstance(event, fx.AdvertiseServices | fx.UnadvertiseServices):
            self._events.emit(self._graph())
        elif isinstance(event, fx.ServiceCallResponse):
            self._calls.resolve(event.call_id, event)
        elif isinstance(event, fx.ServiceCallFailure):
            svc = self._engine.services.get(event.service_id)
            name = svc.name if svc is not None else f"#{event.service_id}"
            if not self._calls.fail(event.call_id, ServiceError(name, event.message)):
                self._log.warning(
                    "serviceCallFailure for unknown call %d: %s",
                    event.call_id,
                    truncate_for_log(event.message),
                )
        elif isinstance(event, fx.ParameterValues):
            values = {p.name: p.value for p in event.parameters}
            if event.id is None or not self._params.resolve(event.id, values):
                self._events.emit(ParameterValues(values))
        elif isinstance(event, fx.Time):
            self._events.emit(ServerClock(event.timestamp_ns))
        elif isinstance(event, fx.Status):
            name, level = _LEVELS.get(event.level, _LEVELS[2])
            self._log.log(level, "server status: %s", truncate_for_log(event.message))
            if event.id is not None:
                self._statuses.pop(event.id, None)  # (re-inserted last: the newest)
                self._statuses[event.id] = (event.message, level)
                if len(self._statuses) > _STATUS_IDS_KEPT:  # the oldest goes
                    del self._statuses[next(iter(self._statuses))]
            self._events.emit(ServerStatus(name, event.message, event.id))
        elif isinstance(event, fx.RemoveStatus):
            for status_id in event.ids:
                message, level = self._statuses.pop(status_id, ("", logging.INFO))
                shown = f": {truncate_for_log(message)}" if message else ""
                self._log.log(level, "server status %s withdrawn%s", status_id, shown)
            self._events.emit(StatusRemoved(event.ids))
        elif isinstance(event, fx.FetchAssetResponse):
            if not self.assets.on_response(event):
                self._log.warning("fetchAsset answer for unknown request %d", event.request_id)
        elif isinstance(event, fx.ConnectionGraphUpdate):
            self.node_list.on_update(event)
        elif isinstance(event, fx.PlaybackState):
            state = self.playback.on_state(event)
            if state is None:
                self._events.reject("malformed", f"playback state of unknown status {event.status}")
            else:
                self._events.emit(state)
        elif isinstance(event, fx.ServerInfo):
            # A later serverInfo resets the server's tables; the engine has
            # already reported the old channels and services as unadvertised.
            self.server_info = self._server_info(event)
            self._offer_parameters()
            self._decoders.clear()
            self._events.emit(self._graph())
        elif isinstance(event, fx.ProtocolViolation):
            self._events.reject(event.kind, event.reason, event.count)
        elif isinstance(event, fx.MessageData):
            self._events.pending.append(self._frame(event, time.time_ns()))

    async def _subscribe_channel(self, channel: fx.Channel) -> None:
        await self._prepare_decoder(channel)
        if self._engine.channels.get(channel.id) is not channel or channel.topic in self._active:
            # re-advertised, withdrawn or subscribed while the decoder was
            # built: the newer event handles it
            return
        sub_id, message = self._engine.subscribe(channel.id)
        self._active[channel.topic] = sub_id
        await self._ws.send(message)
        self._events.emit(TopicState(channel.topic, True))

    # -- bandwidth mode (SubscribeHints.pause_hz) -----------------------------
    async def _saved_frame(self, event: fx.MessageData, received_ns: int) -> None:
        """A message on a topic that pauses after each one: skip it when it
        is the server's replay of the message delivered last, else hand it
        up and unsubscribe until the next one is due (see
        :class:`PauseSchedule`)."""
        channel = event.channel
        topic = channel.topic
        now = anyio.current_time()
        if not self._pauses.take(topic, now, event.payload):
            self._events.emit(Replayed(topic, event.payload.nbytes))  # wait for the next one
            return
        self._events.pending.append(self._frame(event, received_ns))
        sub_id = self._active.pop(topic, None)
        if sub_id is None:  # a late frame after an unsubscribe: nothing to pause
            return
        self._pauses.pause(topic, now, channel)
        await self._ws.send(self._engine.unsubscribe([sub_id]))

    async def _resume_paused(self) -> None:
        """Subscribe each paused topic again when its next message is due
        (the reader's task group runs it)."""
        try:
            await self._pauses.run(self._resume)
        except ConnectError:
            return  # the reader reports the lost connection

    async def _resume(self, topic: str, paused_on: fx.Channel) -> None:
        """Subscribe ``topic`` again after a pause (on the channel that now
        carries it); its first message is checked for a replay."""
        channel = self._channel_for(topic)
        if channel is None or topic not in self._wanted:
            self._pauses.unpause(topic)
            return
        if self._engine.channels.get(channel.id) is not paused_on:
            await self._subscribe_channel(channel)  # another channel: a fresh start
            self._events.post()
            return
        sub_id, message = self._engine.subscribe(channel.id)
        self._active[topic] = sub_id
        self._pauses.resumed(topic, anyio.current_time())
        await self._ws.send(message)

    # -- subscriptions ------------------------------------------------------
    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        self._ws.end_hold()  # a new subscription may want every frame: decide again
        self._wanted[topic] = hints
        self._pauses.set_rate(topic, hints.pause_hz)
        if hints.pause_hz is None and (paused := self._pauses.unpause(topic)) is not None:
            await self._resume(topic, paused[1])
            self._pauses.unpause(topic)  # no replay check: every message is wanted now
        if topic in self._active or topic in self._pauses.paused:
            return
        channel = self._channel_for(topic)
        if channel is not None:
            await self._subscribe_channel(channel)
            self._events.post()

    async def unsubscribe(self, topic: str) -> None:
        self._wanted.pop(topic, None)
        self._pauses.forget(topic)  # paused: no server subscription is left
        sub_id = self._active.pop(topic, None)
        if sub_id is not None:
            await self._ws.send(self._engine.unsubscribe([sub_id]))

    # -- publishing ---------------------------------------------------------
    def _publish_encoding(self, schema: str) -> str:
        supported = self.server_info.supported_encodings
        if "cdr" in supported and self.codecs.has_schema(schema):
            return "cdr"
        if "json" in supported or not supported:
            return "json"
        if "cdr" in supported:
            raise SchemaError(
                f"the server only accepts CDR and no definition of {schema!r} is known"
            )
        raise NotSupportedError(f"the server accepts none of our encodings: {', '.join(supported)}")

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
        if latch:
            raise NotSupportedError("the Foxglove protocol has no latched publishing")
        if best_effort:
            raise NotSupportedError("the Foxglove protocol has no best-effort publishing")
        if await self._pubs.reuse(topic, schema):
            return
        if "clientPublish" not in self.server_info.capabilities:
            raise NotSupportedError(
                "the server does not accept client publishing (no clientPublish)"
            )
        encoding = self._publish_encoding(schema)
        encode = self.codecs.encoder(schema, encoding)
        channel_id, message = self._engine.advertise(topic, encoding, schema)
        ready = anyio.Event()
        self._pubs[topic] = _ClientChannel(schema, ready, channel_id, topic, encoding, encode)
        try:
            await self._ws.send(message)
            await anyio.sleep(self._options.advertise_settle)
        except BaseException:
            self._pubs.pop(topic, None)
            raise
        finally:
            ready.set()

    async def unadvertise(self, topic: str) -> None:
        channel = self._pubs.pop(topic, None)
        if channel is not None:
            await self._ws.send(self._engine.unadvertise([channel.id]))

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        channel = self._pubs[topic]
        payload = channel.encode(data)
        return self._engine.message_data(channel.id, payload)

    # -- services -----------------------------------------------------------
    def _request_codec(self, svc: fx.ServiceDef, empty: bool) -> tuple[str, Any]:
        """(wire encoding, encoder), or an encoder of None meaning "send the
        bare CDR header": the server sent no request schema and the request
        is empty. A non-empty request without a server schema falls back to
        the bundled definitions."""
        req_name, _ = CodecRegistry.service_type_names(svc.type)
        schema = svc.request
        encoding = schema.encoding if schema is not None and schema.encoding else "cdr"
        has_text = schema is not None and bool(schema.schema)
        if schema is not None:
            req_name = schema.schema_name or req_name
            if has_text:
                self.codecs.add_schema(req_name, schema.schema_encoding or "ros2msg", schema.schema)
        if encoding == "json":
            return encoding, self.codecs.encoder(req_name, encoding)
        if has_text or (not empty and self.codecs.has_schema(req_name)):
            return encoding, self.codecs.encoder(req_name, encoding)
        return encoding, None

    def _response_decoder(self, svc: fx.ServiceDef, encoding: str) -> Decoder | None:
        _, res_name = CodecRegistry.service_type_names(svc.type)
        schema = svc.response
        if schema is not None:
            res_name = schema.schema_name or res_name
            if schema.schema:
                self.codecs.add_schema(res_name, schema.schema_encoding or "ros2msg", schema.schema)
        try:
            return self.codecs.decoder(res_name, encoding)
        except SchemaError:
            return None

    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        if "services" not in self.server_info.capabilities:
            raise NotSupportedError("the server does not offer service calls")
        svc = self._service_for(name)
        if svc is None:
            raise ServiceError(name, "the server does not advertise this service")
        empty = not request.__ros_fields__ if isinstance(request, RosMessage) else not request
        try:
            encoding, encode = self._request_codec(svc, empty)
        except SchemaError as exc:
            raise ServiceError(name, f"request schema: {exc}") from exc
        if encode is None:
            if not empty:
                raise ServiceError(
                    name,
                    f"the server sent no request schema for {svc.type} and none is bundled; "
                    "only an empty request can be sent",
                )
            payload: bytes = _EMPTY_CDR
        else:
            payload = encode(request if request is not None else {})
        self._check_pending(name)
        call_id = next(self._call_ids)
        request_frame = self._engine.service_call_request(svc.id, call_id, encoding, payload)
        response: fx.ServiceCallResponse = await self._calls.request(
            call_id, lambda: self._send_request(request_frame)
        )
        decode = self._response_decoder(svc, response.encoding)
        if decode is None:
            return bytes(response.payload)
        try:
            return decode(response.payload)
        except DecodeError as exc:
            raise ServiceError(name, f"the response does not decode: {exc}") from exc

    # -- requests -----------------------------------------------------------
    def _check_pending(self, what: str) -> None:
        """``ServiceError`` at once when ``max_pending_requests`` requests
        already wait for an answer on this connection."""
        waiting = len(self._calls) + len(self._params)
        waiting += len(self.assets.requests) + len(self.playback.requests)
        check_pending(self._options, waiting, what)

    # -- lifecycle ----------------------------------------------------------
    async def send(self, message: WireMessage) -> None:
        await self._ws.send(socket_frame(message))

    async def confirm_delivery(self) -> None:
        pong = await self._ws.ping()
        await pong.wait()  # (also set when the connection closes)
        if self._ws.closed:
            raise connection_lost("the server did not answer the ping before the socket closed")

    def fail_pending(self, error: Exception) -> None:
        assert isinstance(error, RosBridgeError)
        self._calls.fail_all(error)
        self._params.fail_all(error)
        self.assets.requests.fail_all(error)
        self.playback.requests.fail_all(error)
        self.node_list.fail(error)

    async def keepalive(self) -> None:
        interval = self._options.keepalive_interval
        if interval > 0:
            await self._ws.keepalive(
                interval, self._options.keepalive_timeout, self._options.report_latency
            )

    @property
    def bytes_received(self) -> int:
        return self._ws.bytes_received

    @property
    def messages_received(self) -> int:
        return self._ws.messages_received

    def publishing(self) -> Mapping[str, str]:
        return self._pubs.schemas()

    def advertised(self, topic: str) -> str | None:
        return self._pubs.ready_schema(topic)

    @property
    def closed(self) -> bool:
        return self._ws.closed

    async def aclose(self) -> None:
        await self._ws.aclose()
