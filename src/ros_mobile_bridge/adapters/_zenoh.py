"""The Zenoh adapter: ROS 2 over Zenoh with rmw_zenoh's conventions (key
expressions, liveliness tokens, attachments, CDR payloads), through one
zenoh *client* session to a router (``rmw_zenohd`` or any zenoh router).

What it maps:

* the graph: liveliness tokens under ``@ros2_lv/<domain>/``, read once at
  start (a liveliness get) and followed by a liveliness subscriber; keyed by
  the whole token (node and entity ids restart at 0 in every process);
* subscriptions: one zenoh subscriber per topic on
  ``<domain>/<name>/*/*`` (any type and hash), so a publisher whose token
  has not been seen yet still delivers; each sample's key names its type,
  which picks the decoder; a sample without an attachment in a form a
  released rmw_zenoh sends (``wire.rmw_zenoh``) is skipped and counted, as
  ``rmw_zenoh_cpp`` subscribers do;
* publishing: one zenoh publisher per advertised topic on the exact key
  (the type's RIHS01 hash included), with the attachment and increasing
  sequence numbers, and a publisher token so ROS tools see it;
* services: a zenoh ``get`` on the service key with the attachment and a
  deadline; the first reply is the response;
* serving a service: a complete queryable on the service key and a service
  token, each query one call (``adapters/_zenoh_serving.py``);
* actions: the action's ``_action/send_goal``, ``get_result`` and
  ``cancel_goal`` services and its ``_action/feedback`` topic;
* parameters: the nodes' standard ``rcl_interfaces`` parameter services,
  names written ``/node:param`` as over rosbridge; watching them is one
  internal ``/parameter_events`` subscription
  (``adapters/_zenoh_parameter_events.py``).

Our own node token (``rmb_<zid>``) and one token per publisher,
subscription, service client and served service make this client visible
to ROS tools.

Everything the zenoh threads deliver reaches the reader task through the
session's :class:`~ros_mobile_bridge.transport.Inbox`, in batches."""

from __future__ import annotations

import contextlib
import itertools
import logging
import struct
import time
from dataclasses import dataclass
from typing import Any, Final

import anyio

from .._errors import (
    ConnectError,
    NotSupportedError,
    RosBridgeError,
    SchemaError,
)
from .._options import ClientOptions
from .._types import ServerInfo, ServiceInfo, TopicInfo
from ..codec import same_type_name, type_hash
from ..flow import PendingRequests, RawFrame, TopicMessage, WireMessage
from ..transport._zenoh import ZenohSession
from ..wire import rmw_zenoh as rz
from ..wire._limits import truncate_for_log
from ._pauses import PauseSchedule
from ._seam import EventSink, GraphChanged, SubscribeHints, TopicState
from ._shared import (
    Advertisement,
    Advertisements,
    EventSource,
    Publishes,
    codec_registry,
)
from ._zenoh_calls import ZenohCalls
from ._zenoh_describe import ZenohDescribe
from ._zenoh_parameter_events import ZenohParameterEvents
from ._zenoh_serving import ZenohServing
from ._zenoh_values import (
    Goal,
    Query,
    Subscription,
    default_domain,
    parameter_from_ros,
    parameter_to_ros,
)

__all__ = [
    "ZenohAdapter",
    "default_domain",
    "open_zenoh",
    "parameter_from_ros",
    "parameter_to_ros",
]

_GRAPH_TAG: Final = 0
_FIXED: Final = rz.ATTACHMENT_SIZE
_GID_SIZE: Final = 16
_DELIVER_EVERY: Final = 32
"""Frames the reader hands up at once while a long batch is read, then lets
the consumers have a turn (see :meth:`ZenohAdapter._hand_up`)."""
_HEAD: Final = struct.Struct("<qqB")
"""The fixed attachment form's head: sequence number, source timestamp, gid length."""
_MAX_KEYS_PER_TOPIC: Final = 16
"""Distinct (type, hash) keys remembered per subscribed topic; a sample on a
further key is decoded without the cache (a hostile peer cannot grow it)."""


@dataclass(slots=True)
class _Publisher(Advertisement):
    topic: str
    key: str
    gid: bytes
    encode: Any
    publisher: Any
    token: int
    seq: int = 0


async def open_zenoh(endpoint: str, options: ClientOptions) -> ZenohAdapter:
    """Open a zenoh client session to the router at ``endpoint`` and read
    the domain's graph, within ``options.connect_timeout``. ``ConnectError``
    when the router is refused or unreachable."""
    deadline = anyio.current_time() + options.connect_timeout
    session = await ZenohSession.open(
        endpoint,
        connect_timeout=options.connect_timeout,
        shared_memory=options.zenoh_shared_memory,
        max_items=options.zenoh_backlog,
        max_bytes=options.zenoh_backlog_bytes,
    )
    try:
        adapter = ZenohAdapter(session, options, endpoint)
        await adapter.bootstrap(deadline)
    except BaseException:
        await session.aclose()
        raise
    return adapter


_HOLD: Final = object()
""":meth:`ZenohAdapter._decoder_for`: hold the samples, the type is being fetched."""


@dataclass(slots=True)
class _Held:
    """The samples of one topic (key, payload, attachment), in order, held
    while the type of one of its keys is being described."""

    type_name: str
    type_hash: str
    samples: list[tuple[str, bytes, bytes | None]]


class ZenohAdapter(
    ZenohCalls, ZenohDescribe, ZenohParameterEvents, ZenohServing, EventSource, Publishes
):
    """One zenoh session to one router (see :class:`~.Adapter`)."""

    protocol = "zenoh"
    wire_timeout_slack = 0.0  # the client's deadline is the query's timeout

    def __init__(self, session: ZenohSession, options: ClientOptions, endpoint: str) -> None:
        self._session = session
        self._options = options
        self._log: logging.Logger = options.logger
        domain = options.domain_id
        self.domain = default_domain() if domain is None else domain
        self.codecs = codec_registry(options)
        self.server_info = ServerInfo(
            name=f"zenoh router at {endpoint}",
            protocol=self.protocol,
            subprotocol="rmw_zenoh",
            capabilities=("clientPublish", "services", "serving", "actions", "parameters"),
            supported_encodings=("cdr",),
            metadata={"domain_id": str(self.domain), "zid": session.zid},
            session_id=session.zid,
        )
        self._events = EventSource()
        self._init_describe()
        self._held: dict[str, _Held] = {}  # topic -> samples waiting for a description
        self._ids = itertools.count(0)  # node and entity ids, as rmw_zenoh counts them
        self._tags = itertools.count(1)  # inbox tags (0 is the graph)
        self._node_id = next(self._ids)
        self._node_name = f"rmb_{session.zid[:12]}"
        self._graph: dict[str, rz.Token] = {}
        self._topic_infos: list[TopicInfo] = []
        self._service_infos: list[ServiceInfo] = []
        self._publishers_of: dict[str, int] = {}  # topic -> publisher tokens seen
        self._wanted: dict[str, SubscribeHints] = {}
        self._subs: dict[str, Subscription] = {}
        self._by_tag: dict[int, Subscription] = {}
        # save_bandwidth: a paused topic's subscriber is undeclared (the
        # router stops sending) until its next message is due
        self._pauses: PauseSchedule[None] = PauseSchedule()
        self._pubs: Advertisements[_Publisher] = Advertisements()
        self._client_gids: dict[str, tuple[bytes, int]] = {}  # service -> (gid, token)
        self._call_seq = itertools.count(1)
        self._queries: dict[int, Query] = {}
        self._calls: PendingRequests[list[tuple[bool, bytes, bytes | None]]] = PendingRequests()
        self._goals: dict[bytes, Goal] = {}
        self._feedback_subs: dict[str, Subscription] = {}
        self._init_parameter_events()
        self._served = {}
        self._served_by_tag = {}
        self._open_calls = {}
        self._refused_seen = 0
        self._lost: str | None = None
        self._bootstrapped = False
        self._node_key = self._token_key(rz.EntityKind.NODE, self._node_id)
        self._node_token = session.declare_token(self._node_key)
        # (parts: the adapter is each of them until they are objects of their own)
        self.node_list = self
        self.parameters = self
        self.actions = self
        self.serving = self
        self.descriptions = self

    # -- identity ---------------------------------------------------------------------
    def _token(
        self,
        kind: rz.EntityKind,
        entity_id: int,
        name: str | None = None,
        type_name: str | None = None,
        hash_: str | None = None,
        qos: rz.Qos | None = None,
    ) -> rz.Token:
        return rz.Token(
            domain=self.domain,
            zid=self._session.zid,
            node_id=self._node_id,
            entity_id=entity_id,
            kind=kind,
            enclave="",
            namespace="/",
            node_name=self._node_name,
            name=name,
            type_name=type_name,
            type_hash=hash_,
            qos=qos,
        )

    def _token_key(self, kind: rz.EntityKind, entity_id: int, **kw: Any) -> str:
        return rz.format_token(self._token(kind, entity_id, **kw))

    def _type_hash(self, type_name: str) -> str:
        """The RIHS01 hash of ``type_name``; ``SchemaError`` when a nested
        definition is missing (a wrong hash would reach nobody, silently)."""
        return type_hash(self.codecs, type_name)

    def _key(self, name: str, type_name: str) -> str:
        return rz.format_key(rz.TopicKey(self.domain, name, type_name, self._type_hash(type_name)))

    # -- the graph ----------------------------------------------------------------------
    async def bootstrap(self, deadline: float) -> None:
        """Read the graph as it is now (a liveliness get), then follow it.
        Called once, by :func:`open_zenoh`."""
        session = self._session
        selector = rz.liveliness_selector(self.domain)
        query_id = session.query_liveliness(
            selector, timeout=max(deadline - anyio.current_time(), 0.001)
        )
        done = False
        with anyio.move_on_after(max(deadline - anyio.current_time(), 0.0)):
            while not done:
                for item in await session.inbox.get_batch():
                    if type(item) is rz.QueryDone and item.query_id == query_id:
                        done = True
                    else:
                        self._handle_early(item)
        if not done:
            raise ConnectError("zenoh: the router did not answer the graph query in time")
        session.subscribe_liveliness(selector, _GRAPH_TAG)
        self._rebuild_graph()
        self._bootstrapped = True

    def _handle_early(self, item: rz.InboxItem) -> None:
        if type(item) is rz.Reply:
            if item.ok and item.key is not None:
                self._on_token(item.key, True)
        elif type(item) is rz.LivelinessChange:
            self._on_token(item.key, item.alive)

    def _on_token(self, key: str, alive: bool) -> bool:
        """Follow one liveliness change; True when the graph changed."""
        if not alive:
            return self._graph.pop(key, None) is not None
        if key in self._graph:
            return False
        try:
            token = rz.parse_token(key)
        except rz.MalformedKey as exc:
            self._events.reject("malformed_token", f"{key}: {exc}")
            return False
        if token.domain != self.domain:
            return False
        if len(self._graph) >= self._options.max_channels:
            self._events.reject(
                "channel_limit", f"more than {self._options.max_channels} graph tokens"
            )
            return False
        self._graph[key] = token
        return True

    def _rebuild_graph(self) -> None:
        topics: dict[str, str] = {}
        publishers: dict[str, int] = {}
        services: dict[str, str] = {}
        for token in self._graph.values():
            if token.name is None or token.type_name is None:
                continue
            if token.kind in (rz.EntityKind.PUBLISHER, rz.EntityKind.SUBSCRIPTION):
                if token.kind is rz.EntityKind.PUBLISHER or token.name not in topics:
                    topics[token.name] = token.type_name
                if token.kind is rz.EntityKind.PUBLISHER:
                    publishers[token.name] = publishers.get(token.name, 0) + 1
            elif token.kind is rz.EntityKind.SERVICE:
                services[token.name] = token.type_name
        self._topic_infos = [TopicInfo(n, t, "cdr") for n, t in sorted(topics.items())]
        self._service_infos = [ServiceInfo(n, t) for n, t in sorted(services.items())]
        before = self._publishers_of
        self._publishers_of = publishers
        for topic in self._wanted:
            was, now = topic in before, topic in publishers
            if was != now:
                self._events.emit(TopicState(topic, now))
        for topic, sub in self._subs.items():
            if sub.token is None and topic in topics:
                self._declare_subscription_token(sub, topics[topic])

    @property
    def topics(self) -> list[TopicInfo]:
        return list(self._topic_infos)

    @property
    def services(self) -> list[ServiceInfo]:
        return list(self._service_infos)

    def topic_active(self, topic: str) -> bool:
        return topic in self._publishers_of

    @property
    def bytes_received(self) -> int:
        return self._session.inbox.bytes_received

    @property
    def messages_received(self) -> int:
        return self._session.inbox.items_received

    def offered_qos(self, topic: str) -> list[rz.Qos]:
        """The QoS of each live publisher of ``topic``, from their liveliness
        tokens (what a recording writes as ``offered_qos_profiles``)."""
        return [
            token.qos
            for token in self._graph.values()
            if token.kind is rz.EntityKind.PUBLISHER and token.name == topic and token.qos
        ]

    def _topic_type(self, topic: str) -> str | None:
        for info in self._topic_infos:
            if info.name == topic:
                return info.schema_name
        return None

    def _service_type(self, name: str) -> str | None:
        for info in self._service_infos:
            if info.name == name:
                return info.type
        return None

    # -- the reader -----------------------------------------------------------------------
    async def run(self, sink: EventSink) -> None:
        lost: ConnectError | None = None
        async with anyio.create_task_group() as group:
            self._describe_group = group  # type descriptions are fetched in its tasks
            group.start_soon(self._pauses.run, self._resume)
            try:
                await self._read(sink)
            except ConnectError as exc:
                lost = exc
                group.cancel_scope.cancel()
            finally:
                self._describe_group = None
        if lost is not None:
            raise lost

    async def _read(self, sink: EventSink) -> None:
        self._events.attach(sink)
        inbox = self._session.inbox
        by_tag = self._by_tag
        saving = self._pauses.rates  # (updated in place)
        pace_below = self._options.zenoh_backlog // 2
        while True:
            if self._lost is not None:
                raise ConnectError(f"zenoh: {self._lost}")
            batch = await inbox.get_batch()
            graph_changed = False
            requests: list[rz.Request] = []
            # samples taken and not yet read: while they and those waiting in
            # the inbox are under half its bound, the consumers get a turn
            # every _DELIVER_EVERY frames (see _hand_up)
            left = sum(len(item.samples) for item in batch if type(item) is rz.Samples)
            for item in batch:
                if type(item) is rz.Samples:
                    left -= len(item.samples)
                    sub = by_tag.get(item.tag)
                    if sub is None:
                        pass  # its subscriber was undeclared since
                    elif sub.feedback_of is not None:
                        for _key, payload, attachment in item.samples:
                            self._on_feedback(sub, payload, attachment)
                    elif sub.parameter_events:
                        for key, payload, attachment in item.samples:
                            self._on_parameter_event(key, payload, attachment)
                    else:
                        samples, at = item.samples, item.receive_time_ns
                        for start in range(0, len(samples), _DELIVER_EVERY):
                            built = len(self._events.pending)
                            self._on_samples(sub, samples[start : start + _DELIVER_EVERY], at)
                            if saving and sub.topic in saving and len(self._events.pending) > built:
                                self._pause(sub)
                            if len(self._events.pending) >= _DELIVER_EVERY:
                                behind = left + len(samples) - start + inbox.waiting[0]
                                await self._hand_up(behind < pace_below)
                elif type(item) is rz.LivelinessChange:
                    graph_changed |= self._on_token(item.key, item.alive)
                elif type(item) is rz.Reply:
                    query = self._queries.get(item.query_id)
                    if query is not None:
                        query.replies.append((item.ok, item.payload, item.attachment))
                elif type(item) is rz.QueryDone:
                    self._on_query_done(item.query_id)
                elif type(item) is rz.Request:
                    requests.append(item)
                elif type(item) is rz.SessionLost:
                    self._lost = item.reason
            overflowed = inbox.overflowed
            if overflowed:
                inbox.overflowed = 0
                by = dict(inbox.overflowed_by_tag)
                inbox.overflowed_by_tag.clear()
                for tag, count in by.items():
                    sub = by_tag.get(tag)
                    what = sub.topic if sub is not None else f"tag {tag}"
                    self._events.reject(
                        "backlog_overflow",
                        f"{what}: the reader fell behind by more than the zenoh backlog",
                        count,
                    )
            if graph_changed:
                self._rebuild_graph()
                self._events.emit(GraphChanged(self.topics, self.services))
            for request in requests:
                await self._on_request(request)
            self._count_refused_queries()
            await self._events.deliver()

    async def _hand_up(self, pace: bool) -> None:
        """Hand the frames built so far up; with ``pace``, then give the other
        tasks (the consumers) a turn before building more. Without it the
        reader, which builds a frame faster than a consumer decodes one,
        turns a burst waiting in the inbox into queued frames at once, and a
        backlog of frames (two objects the garbage collector tracks each)
        costs full collections, where the inbox's plain tuples cost none.
        Not backpressure: the reader goes on after the turn whatever the
        consumers took. The reader paces itself only while the samples
        behind it are under half the inbox's bound: past that it reads
        ahead, so that under a lasting overload the subscriptions' own
        policies (``buffer``, ``dispatch``) choose what is dropped, not the
        inbox (which can only refuse the newest)."""
        await self._events.deliver()
        if pace:
            await anyio.lowlevel.checkpoint()

    def _on_samples(
        self, sub: Subscription, samples: list[rz.SampleData], receive_time_ns: int
    ) -> None:
        """A batch of one subscription's data samples to frames, in order.
        The common case is read here: a key seen before, the topic's type not
        being described, the fixed attachment form (one ``unpack_from``);
        anything else goes through :meth:`_on_sample`."""
        keys = sub.keys
        held = self._held
        topic = sub.topic
        unpack = _HEAD.unpack_from
        for key, payload, attachment in samples:
            entry = keys.get(key)
            if (
                entry is None
                or attachment is None
                or len(attachment) != _FIXED
                or (held and topic in held)
            ):
                self._on_sample(sub, key, payload, attachment, receive_time_ns)
                continue
            sequence, stamp, gid_size = unpack(attachment)
            if gid_size != _GID_SIZE:
                self._on_sample(sub, key, payload, attachment, receive_time_ns)
                continue
            # self._events.pending each time: an event handed up in between replaces it
            self._events.pending.append(
                RawFrame(
                    topic,
                    entry[0],
                    "cdr",
                    memoryview(payload),
                    stamp if stamp > 0 else None,
                    receive_time_ns,
                    entry[1],
                    sequence,
                )
            )

    def _on_sample(
        self,
        sub: Subscription,
        key: str,
        payload: bytes,
        attachment: bytes | None,
        receive_time_ns: int | None = None,
    ) -> None:
        """One data sample to a frame (or held, or skipped and counted): the
        general case of :meth:`_on_samples`, and the held samples' replay."""
        if attachment is not None and len(attachment) == _FIXED and attachment[16] == _GID_SIZE:
            sequence, stamp, _ = _HEAD.unpack_from(attachment)
        else:  # the older keyed form, or nothing readable
            try:
                older = rz.decode_attachment(attachment)
            except rz.MalformedAttachment:
                self._events.reject(
                    "attachment",
                    f"{sub.topic}: a sample without a valid rmw_zenoh attachment "
                    f"({'none' if attachment is None else f'{len(attachment)} bytes'})",
                )
                return
            stamp, sequence = older.timestamp_ns, older.sequence
        if self._held and sub.topic in self._held:  # its type is being described
            self._hold(sub.topic, self._held[sub.topic], key, payload, attachment)
            return
        entry = sub.keys.get(key)
        if entry is None:
            built = self._key_entry(sub.topic, key)
            if built is None:
                return
            if built[1] is _HOLD:
                parsed = rz.parse_key(key)
                held = self._held[sub.topic] = _Held(parsed.type_name, parsed.type_hash, [])
                self._hold(sub.topic, held, key, payload, attachment)
                return
            entry = built
            if len(sub.keys) < _MAX_KEYS_PER_TOPIC:
                sub.keys[key] = entry
        schema, decode = entry
        self._events.pending.append(
            RawFrame(
                sub.topic,
                schema,
                "cdr",
                memoryview(payload),
                stamp if stamp > 0 else None,
                time.time_ns() if receive_time_ns is None else receive_time_ns,
                decode,
                sequence,
            )
        )

    def _hold(
        self, topic: str, held: _Held, key: str, payload: bytes, attachment: bytes | None
    ) -> None:
        if len(held.samples) >= self._options.type_description_hold:
            self._events.reject(
                "description_hold_overflow",
                f"{topic}: more than {self._options.type_description_hold} samples arrived "
                f"while the description of {held.type_name} was fetched "
                "(type_description_hold)",
            )
            return
        held.samples.append((key, payload, attachment))

    def _on_described(self, type_name: str, type_hash: str) -> None:
        """A fetch of (type, hash) ended: the samples held for it are decoded
        (or delivered raw, when it failed), in order, and handed up."""
        for topic, held in list(self._held.items()):
            if (held.type_name, held.type_hash) != (type_name, type_hash):
                continue
            del self._held[topic]
            sub = self._subs.get(topic)
            if sub is None:
                continue
            for key, payload, attachment in held.samples:
                self._on_sample(sub, key, payload, attachment)
        self._events.post()

    def _key_entry(self, topic: str, key: str) -> tuple[str, Any] | None:
        """The type and decoder for samples on ``key``; None (counted) for a
        key that is not a well-formed rmw_zenoh data key of ``topic``."""
        try:
            parsed = rz.parse_key(key)
        except rz.MalformedKey as exc:
            self._events.reject("malformed", f"{topic}: data key {key!r}: {exc}")
            return None
        if parsed.name != topic or parsed.domain != self.domain:
            self._events.reject("malformed", f"{topic}: data key {key!r} names another topic")
            return None
        return parsed.type_name, self._decoder_for(parsed)

    def _decoder_for(self, parsed: rz.TopicKey) -> Any:
        """A decoder when we know a definition whose hash is the key's;
        :data:`_HOLD` while the robot is asked for it (hold the samples);
        None (messages delivered raw, with a warning) otherwise: decoding
        with another definition of the same name would deliver garbage."""
        if self._knows(parsed.type_name, parsed.type_hash):
            return self.codecs.decoder(parsed.type_name, "cdr")
        name, hash_ = parsed.type_name, parsed.type_hash
        if (
            self._describe_failed(name, hash_) is None
            and self._describers(name, hash_)
            and self._want_description(name, hash_)
        ):
            return _HOLD
        try:
            ours = self._type_hash(parsed.type_name)
            if ours != parsed.type_hash:
                self._log.warning(
                    "%s: the publisher's %s has hash %s, ours %s (another definition);"
                    " messages are delivered raw",
                    parsed.name,
                    parsed.type_name,
                    parsed.type_hash,
                    ours,
                )
                return None
            return self.codecs.decoder(parsed.type_name, "cdr")
        except SchemaError as exc:
            self._log.warning(
                "%s: no decoder for %s, messages will be delivered raw: %s",
                parsed.name,
                parsed.type_name,
                truncate_for_log(str(exc)),
            )
            return None

    def _on_query_done(self, query_id: int) -> None:
        query = self._queries.pop(query_id, None)
        if query is None:
            return
        if query.on_done is not None:
            query.on_done(query.replies)
        else:
            self._calls.resolve(query_id, query.replies)

    # -- subscriptions --------------------------------------------------------------------
    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        self._wanted[topic] = hints
        self._pauses.set_rate(topic, hints.pause_hz)
        if topic in self._subs:
            if hints.pause_hz is None and self._pauses.unpause(topic) is not None:
                await self._resume(topic, None)  # every message is wanted now
                self._pauses.unpause(topic)
            return
        type_name = hints.schema or self._topic_type(topic)
        announced = self._graph_hash(topic, (rz.EntityKind.PUBLISHER,))
        if announced is not None and not self._knows(*announced):
            self._want_description(*announced)  # ahead of the first sample
        elif type_name is not None:
            await self._prepare_decoder(topic, type_name)
        tag = next(self._tags)
        handle = self._session.subscribe(self._data_selector(topic), tag)
        sub = Subscription(topic, tag, handle)
        self._subs[topic] = sub
        self._by_tag[tag] = sub
        if type_name is not None:
            self._declare_subscription_token(sub, type_name)
        if topic in self._publishers_of:
            self._events.emit(TopicState(topic, True))
        self._events.post()

    def _data_selector(self, topic: str) -> str:
        return f"{self.domain}/{topic.lstrip('/')}/*/*"

    def _pause(self, sub: Subscription) -> None:
        """``save_bandwidth``: a message of ``sub`` was taken; undeclare its
        subscriber until the next one is due. Samples already on their way
        still arrive under its tag (the rate cap takes them)."""
        if sub.handle is None:
            return
        now = anyio.current_time()
        self._pauses.take(sub.topic, now)  # times the last resumption (no replays here)
        self._session.undeclare(sub.handle)
        sub.handle = None
        self._pauses.pause(sub.topic, now, None)

    async def _resume(self, topic: str, _: None) -> None:
        """Declare a paused topic's subscriber again, under the same tag. A
        failure to declare it ends the session (the client reconnects)."""
        sub = self._subs.get(topic)
        if sub is None or sub.handle is not None:
            self._pauses.unpause(topic)
            return
        try:
            sub.handle = self._session.subscribe(self._data_selector(topic), sub.tag)
        except Exception as exc:
            self._session.inbox.push(rz.SessionLost(f"cannot subscribe to {topic} again: {exc}"))
            return
        self._pauses.resumed(topic, anyio.current_time())

    async def _prepare_decoder(self, topic: str, type_name: str) -> None:
        """Build the type's decoder (and hash) in a worker thread ahead of
        the first sample: generating it can take tens of milliseconds that
        would otherwise stall the reader."""

        def build() -> None:
            try:
                self._type_hash(type_name)
                self.codecs.decoder(type_name, "cdr")
            except SchemaError:
                pass  # reported when a sample arrives

        await anyio.to_thread.run_sync(build)

    def _declare_subscription_token(self, sub: Subscription, type_name: str) -> None:
        try:
            hash_ = self._type_hash(type_name)
        except SchemaError:
            return
        sub.token = self._session.declare_token(
            self._token_key(
                rz.EntityKind.SUBSCRIPTION,
                next(self._ids),
                name=sub.topic,
                type_name=type_name,
                hash_=hash_,
                qos=rz.Qos(),
            )
        )

    async def unsubscribe(self, topic: str) -> None:
        self._wanted.pop(topic, None)
        sub = self._subs.pop(topic, None)
        if sub is None:
            return
        self._by_tag.pop(sub.tag, None)
        self._held.pop(topic, None)
        self._pauses.forget(topic)
        if sub.handle is not None:
            self._session.undeclare(sub.handle)
        if sub.token is not None:
            self._session.undeclare(sub.token)

    # -- publishing ---------------------------------------------------------------------
    async def advertise(
        self, topic: str, schema: str, *, latch: bool = False, confirm: bool = True
    ) -> None:
        if await self._pubs.reuse(topic, schema):
            return
        if latch:
            raise NotSupportedError(
                "latched (transient-local) publishing is not implemented over zenoh yet"
            )
        encode = self.codecs.encoder(schema, "cdr")
        key = self._key(topic, schema)
        qos = rz.Qos()
        entity_id = next(self._ids)
        token_key = self._token_key(
            rz.EntityKind.PUBLISHER,
            entity_id,
            name=topic,
            type_name=schema,
            hash_=rz.parse_key(key).type_hash,
            qos=qos,
        )
        publisher = self._session.declare_publisher(key, reliable=qos.reliable, express=False)
        token = self._session.declare_token(token_key)
        ready = anyio.Event()
        ready.set()
        self._pubs[topic] = _Publisher(
            schema, ready, topic, key, rz.entity_gid(token_key), encode, publisher, token
        )
        await self._serve_descriptions()

    def _published_types(self) -> list[str]:
        return list(self._pubs.schemas().values())

    async def nodes(self) -> list[str]:
        """The nodes whose liveliness tokens (``NN``) are alive on this
        domain, ours left out; bounded as the graph is (``max_channels``
        tokens)."""
        names = {
            f"{token.namespace.rstrip('/')}/{token.node_name}"
            for key, token in self._graph.items()
            if token.kind is rz.EntityKind.NODE and key != self._node_key
        }
        return sorted(names)

    async def unadvertise(self, topic: str) -> None:
        pub = self._pubs.pop(topic, None)
        if pub is not None:
            self._session.undeclare(pub.token)
            with contextlib.suppress(Exception):
                pub.publisher.undeclare()

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        pub = self._pubs[topic]
        return TopicMessage(topic, pub.encode(data))

    async def send(self, message: WireMessage) -> None:
        if not isinstance(message, TopicMessage):
            raise TypeError("the zenoh adapter sends only TopicMessage")
        if self._lost is not None or self._session.closed:
            raise ConnectError(f"zenoh: {self._lost or 'the session is closed'}")
        pub = self._pubs.get(message.topic)
        if pub is None:
            raise ConnectError(f"{message.topic} is no longer advertised on this session")
        pub.seq += 1
        attachment = rz.encode_attachment(pub.seq, time.time_ns(), pub.gid)
        try:
            pub.publisher.put(message.payload, attachment=attachment)
        except Exception as exc:  # a closed session
            raise ConnectError(f"zenoh: put failed: {exc}") from exc

    # -- lifecycle -----------------------------------------------------------------------------
    async def fetch_definition(self, schema: str) -> bool:
        """Known, or learnt from a node of the graph that uses a type of
        that name (REP-2011, see ``_zenoh_describe``): whether a definition
        with the graph's hash is known now. ``SchemaError`` when a node was
        asked and did not tell."""
        announced = self._announced(schema)
        if announced is None:
            return self.codecs.resolves(schema)
        await self._ensure_described(*announced)
        return True

    def _announced(self, schema: str) -> tuple[str, str] | None:
        """(type, hash) of a type named ``schema`` in the graph's tokens."""
        for token in self._graph.values():
            if token.type_name and token.type_hash and same_type_name(token.type_name, schema):
                return token.type_name, token.type_hash
        return None

    async def _round_trip(self, timeout: float) -> bool:
        """A liveliness query for our own node token, answered by the router:
        everything put before it has left this session (zenoh keeps one
        session's order). True when the answer came within ``timeout``."""
        self._check_alive()
        query_id = self._session.query_liveliness(self._node_key, timeout=timeout)
        finished = anyio.Event()
        self._queries[query_id] = Query("round trip", on_done=lambda _r: finished.set())
        with anyio.move_on_after(timeout):
            await finished.wait()
        return finished.is_set()

    def _check_alive(self) -> None:
        if self._lost is not None or self._session.closed:
            raise ConnectError(f"zenoh: {self._lost or 'the session is closed'}")

    async def confirm_delivery(self) -> None:
        await self._round_trip(self._options.teardown_timeout)

    def fail_pending(self, error: Exception) -> None:
        assert isinstance(error, RosBridgeError)
        self._calls.fail_all(error)
        goals, self._goals = self._goals, {}
        for goal in goals.values():
            goal.events.on_failed("disconnected")

    async def keepalive(self) -> None:
        """Watch the router: zenoh's client session reconnects by itself, but
        while it has no router nothing flows, so a router missing for
        ``keepalive_timeout`` counts as a lost connection (the client's
        reconnect policy then opens a new session). Each check is timed
        as the connection's latency."""
        interval = self._options.keepalive_interval
        if interval <= 0:
            await anyio.sleep_forever()
        missing_since: float | None = None
        while not self._session.closed and self._lost is None:
            await anyio.sleep(min(interval, 1.0))
            routers = await anyio.to_thread.run_sync(self._session.routers)
            if routers:
                missing_since = None
                self._retry_results()
                start = time.perf_counter()
                if await self._round_trip(self._options.keepalive_timeout):
                    self._options.report_latency((time.perf_counter() - start) * 1000.0)
                continue
            now = anyio.current_time()
            if missing_since is None:
                missing_since = now
            elif now - missing_since >= self._options.keepalive_timeout:
                self._session.inbox.push(rz.SessionLost("the router is gone"))
                return

    @property
    def closed(self) -> bool:
        return self._session.closed

    async def aclose(self) -> None:
        """Close the session: every declaration goes (the served services'
        queryables and tokens too) and the calls still open are answered
        with an error."""
        self._served.clear()
        self._served_by_tag.clear()
        self._open_calls.clear()
        await self._session.aclose()
