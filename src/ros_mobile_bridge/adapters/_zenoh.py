"""The Zenoh adapter: ROS 2 over Zenoh with rmw_zenoh's conventions (key
expressions, liveliness tokens, attachments, CDR payloads), through one
zenoh *client* session to a router (``rmw_zenohd`` or any zenoh router).

What it maps:

* the graph: liveliness tokens under ``@ros2_lv/<domain>/``, read once at
  start (a liveliness get) and followed by a liveliness subscriber; keyed by
  the whole token (node and entity ids restart at 0 in every process)
  (``adapters/_zenoh_graph.py``, also the node list);
* subscriptions: one zenoh subscriber per topic on
  ``<domain>/<name>/*/*`` (any type and hash), so a publisher whose token
  has not been seen yet still delivers; each sample's key names its type,
  which picks the decoder; a sample without an attachment in a form a
  released rmw_zenoh sends (``wire.rmw_zenoh``) is skipped and counted, as
  ``rmw_zenoh_cpp`` subscribers do (``adapters/_zenoh_samples.py``);
* publishing: one zenoh publisher per advertised topic on the exact key
  (the type's RIHS01 hash included), with the attachment and increasing
  sequence numbers, and a publisher token so ROS tools see it;
* services: a zenoh ``get`` on the service key with the attachment and a
  deadline; the first reply is the response (``adapters/_zenoh_calls.py``);
* serving a service: a complete queryable on the service key and a service
  token, each query one call (``adapters/_zenoh_serving.py``);
* actions: the action's ``_action/send_goal``, ``get_result`` and
  ``cancel_goal`` services and its ``_action/feedback`` topic
  (``adapters/_zenoh_actions.py``);
* parameters: the nodes' standard ``rcl_interfaces`` parameter services,
  names written ``/node:param`` as over rosbridge; watching them is one
  internal ``/parameter_events`` subscription
  (``adapters/_zenoh_parameters.py``);
* types: REP-2011 type descriptions asked of the graph's nodes, and served
  for the types this client publishes (``adapters/_zenoh_describe.py``).

Our own node token (``rmb_<zid>``) and one token per publisher,
subscription, service client and served service make this client visible
to ROS tools (``adapters/_zenoh_node.py``: what the parts share).

Everything the zenoh threads deliver reaches the reader task through the
session's :class:`~ros_mobile_bridge.transport.Inbox`, in batches: the core
here reads it and hands each item to the part it is for."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

import anyio

from .._errors import ConnectError, RosBridgeError, SchemaError, ServiceError
from .._options import ClientOptions
from .._types import ServerInfo, ServiceInfo, TopicInfo
from ..flow import TopicMessage, WireMessage
from ..transport._zenoh import ZenohSession
from ..wire import rmw_zenoh as rz
from ._pauses import PauseSchedule
from ._seam import EventSink, GraphChanged, SubscribeHints, TopicState
from ._shared import Advertisement, Advertisements, EventSource, codec_registry
from ._zenoh_actions import ZenohActions
from ._zenoh_calls import ZenohQueries
from ._zenoh_describe import ZenohDescriptions
from ._zenoh_graph import ZenohGraph
from ._zenoh_latched import LatchedMemory, ZenohLatched
from ._zenoh_node import ZenohNode
from ._zenoh_parameters import ZenohParameters
from ._zenoh_samples import ZenohSamples
from ._zenoh_serving import ZenohServing
from ._zenoh_values import (
    Goal,
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
_DELIVER_EVERY: Final = 32
"""Frames the reader hands up at once while a long batch is read, then lets
the consumers have a turn (see :meth:`ZenohAdapter._hand_up`)."""


@dataclass(slots=True)
class _Publisher(Advertisement):
    topic: str
    key: str
    gid: bytes
    encode: Any
    publisher: Any
    token: int
    seq: int = 0


async def open_zenoh(
    endpoint: str, options: ClientOptions, previous: object = None
) -> ZenohAdapter:
    """Open a zenoh client session to the router at ``endpoint`` and read
    the domain's graph, within ``options.connect_timeout``, secured by
    ``options.zenoh_security`` and ``options.zenoh_config``. ``ConnectError``
    naming the cause when the router is refused or unreachable, or the
    link's TLS or authentication fails. ``previous``: the adapter this one
    replaces (a reconnect), whose record of the latched samples delivered
    carries over (``_zenoh_latched``)."""
    deadline = anyio.current_time() + options.connect_timeout
    session = await ZenohSession.open(
        endpoint,
        connect_timeout=options.connect_timeout,
        shared_memory=options.zenoh_shared_memory,
        max_items=options.zenoh_backlog,
        max_bytes=options.zenoh_backlog_bytes,
        security=options.zenoh_security,
        config=options.zenoh_config,
        logger=options.logger,
    )
    try:
        memory = previous.latched.memory if isinstance(previous, ZenohAdapter) else None
        adapter = ZenohAdapter(session, options, endpoint, memory)
        await adapter.bootstrap(deadline)
    except BaseException:
        await session.aclose()
        raise
    return adapter


class ZenohAdapter:
    """One zenoh session to one router (see :class:`~.Adapter`).

    The core here reads the inbox, follows the graph, subscribes, publishes
    and keeps the session alive. It holds its parts, built with what each
    needs (the shared :class:`~._zenoh_node.ZenohNode`, and each other):
    the query engine (:class:`~._zenoh_calls.ZenohQueries`), which the
    others call through, and the optional parts of the seam, none of them
    None over Zenoh: :attr:`node_list` (the graph), :attr:`parameters`,
    :attr:`actions`, :attr:`serving` and :attr:`descriptions`; and the
    samples part (:class:`~._zenoh_samples.ZenohSamples`), the hot path."""

    protocol = "zenoh"
    # a put has no acknowledgement, and the liveliness round trip may be
    # answered by this session itself while the router is silent
    confirms_delivery = False
    wire_timeout_slack = 0.0  # the client's deadline is the query's timeout
    assets: None = None  # Foxglove's alone
    playback: None = None

    def __init__(
        self,
        session: ZenohSession,
        options: ClientOptions,
        endpoint: str,
        memory: LatchedMemory | None = None,
    ) -> None:
        self._session = session
        self._options = options
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
        self._events = events = EventSource()
        self._node = node = ZenohNode(session, options, self.domain, self.codecs, events)
        self._graph = node.graph
        self._routes = node.routes  # inbox tag -> subscription
        self._wanted: dict[str, SubscribeHints] = {}
        self._subs: dict[str, Subscription] = {}
        # save_bandwidth: a paused topic's subscriber is undeclared (the
        # router stops sending) until its next message is due
        self._pauses: PauseSchedule[None] = PauseSchedule()
        self._pubs: Advertisements[_Publisher] = Advertisements()
        self._bootstrapped = False
        # the parts
        goals: dict[bytes, Goal] = {}  # the actions' open goals, counted by the queries
        self._queries = queries = ZenohQueries(node, goals)
        self.serving: ZenohServing = ZenohServing(node, queries)
        self.descriptions: ZenohDescriptions = ZenohDescriptions(
            node,
            queries,
            self.serving,
            published=self.publishing,
            on_described=self._on_described,
        )
        self.actions: ZenohActions = ZenohActions(node, queries, self.descriptions, goals)
        self.parameters: ZenohParameters = ZenohParameters(node, queries)
        self.node_list: ZenohGraph = node.graph
        self._samples = ZenohSamples(node, self.descriptions, self._subs)
        self.latched = ZenohLatched(node, self._samples, self._subs, memory)
        self._node_token = session.declare_token(node.node_key)

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
                self._graph.on_token(item.key, True)
        elif type(item) is rz.LivelinessChange:
            self._graph.on_token(item.key, item.alive)

    def _rebuild_graph(self) -> None:
        """The graph's lists anew; each wanted topic whose publishers came or
        went is reported, and a subscription whose type is now known gets
        its token."""
        before = self._graph.publishers_of
        topics = self._graph.rebuild()
        publishers = self._graph.publishers_of
        for topic in self._wanted:
            was, now = topic in before, topic in publishers
            if was != now:
                self._events.emit(TopicState(topic, now))
        for topic, sub in self._subs.items():
            if sub.token is None and topic in topics:
                self._declare_subscription_token(sub, topics[topic])
        if self._subs:
            self.latched.on_graph()  # history of the transient-local publishers that came
        for retried in self.descriptions.retry_failed():  # a new node to ask
            self._samples.reconsider(*retried)

    @property
    def topics(self) -> list[TopicInfo]:
        return list(self._graph.topic_infos)

    @property
    def services(self) -> list[ServiceInfo]:
        return list(self._graph.service_infos)

    def topic_active(self, topic: str) -> bool:
        return topic in self._graph.publishers_of

    @property
    def bytes_received(self) -> int:
        return self._session.inbox.bytes_received

    @property
    def messages_received(self) -> int:
        return self._session.inbox.items_received

    def offered_qos(self, topic: str) -> list[rz.Qos]:
        """The QoS of each live publisher of ``topic``, from their liveliness
        tokens (what a recording writes as ``offered_qos_profiles``)."""
        return self._graph.offered_qos(topic)

    # -- the reader -----------------------------------------------------------------------
    async def run(self, sink: EventSink) -> None:
        lost: ConnectError | None = None
        async with anyio.create_task_group() as group:
            self.descriptions.group = group  # type descriptions are fetched in its tasks
            group.start_soon(self._pauses.run, self._resume)
            try:
                await self._read(sink)
            except ConnectError as exc:
                lost = exc
                group.cancel_scope.cancel()
            finally:
                self.descriptions.group = None
        if lost is not None:
            raise lost

    async def _read(self, sink: EventSink) -> None:
        self._events.attach(sink)
        node = self._node
        inbox = self._session.inbox
        by_tag = self._routes
        on_samples = self._samples.on_samples
        queries, serving, latched = self._queries, self.serving, self.latched
        saving = self._pauses.rates  # (updated in place)
        pace_below = self._options.zenoh_backlog // 2
        while True:
            if node.lost is not None:
                raise ConnectError(f"zenoh: {node.lost}")
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
                        self.actions.on_feedback(sub, item.samples)
                    elif sub.parameter_events:
                        self.parameters.on_samples(item.samples)
                    else:
                        samples, at = item.samples, item.receive_time_ns
                        for start in range(0, len(samples), _DELIVER_EVERY):
                            built = len(self._events.pending)
                            on_samples(sub, samples[start : start + _DELIVER_EVERY], at)
                            if saving and sub.topic in saving and len(self._events.pending) > built:
                                self._pause(sub)
                            if len(self._events.pending) >= _DELIVER_EVERY:
                                behind = left + len(samples) - start + inbox.waiting[0]
                                await self._hand_up(behind < pace_below)
                elif type(item) is rz.LivelinessChange:
                    graph_changed |= self._graph.on_token(item.key, item.alive)
                elif type(item) is rz.Reply:
                    if not latched.on_reply(item):
                        queries.on_reply(item)
                elif type(item) is rz.QueryDone:
                    if not latched.on_done(item.query_id):
                        queries.on_done(item.query_id)
                elif type(item) is rz.Request:
                    requests.append(item)
                elif type(item) is rz.SessionLost:
                    node.lost = item.reason
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
                await serving.on_request(request)
            serving.count_refused_queries()
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

    def _on_described(self, type_name: str, type_hash: str) -> None:
        """A fetch of (type, hash) ended (the descriptions part says so):
        the samples held for it go on."""
        self._samples.release(type_name, type_hash)

    # -- subscriptions --------------------------------------------------------------------
    async def subscribe(self, topic: str, hints: SubscribeHints) -> None:
        self._wanted[topic] = hints
        self._pauses.set_rate(topic, hints.pause_hz)
        if topic in self._subs:
            if hints.pause_hz is None and self._pauses.unpause(topic) is not None:
                await self._resume(topic, None)  # every message is wanted now
                self._pauses.unpause(topic)
            return
        type_name = hints.schema or self._graph.topic_type(topic)
        announced = self._graph.graph_hash(topic, (rz.EntityKind.PUBLISHER,))
        if announced is not None and not self.descriptions.knows(*announced):
            self.descriptions.want(*announced)  # ahead of the first sample
        elif type_name is not None:
            await self._prepare_decoder(topic, type_name)
        tag = self._node.new_tag()
        handle = self._session.subscribe(self._node.data_selector(topic), tag)
        sub = Subscription(topic, tag, handle)
        self._subs[topic] = sub
        self._routes[tag] = sub
        if type_name is not None:
            self._declare_subscription_token(sub, type_name)
        self.latched.watch(sub)
        if topic in self._graph.publishers_of:
            self._events.emit(TopicState(topic, True))
        self._events.post()

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
            sub.handle = self._session.subscribe(self._node.data_selector(topic), sub.tag)
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
                self._node.type_hash(type_name)
                self.codecs.decoder(type_name, "cdr")
            except SchemaError:
                pass  # reported when a sample arrives

        await anyio.to_thread.run_sync(build)

    def _declare_subscription_token(self, sub: Subscription, type_name: str) -> None:
        try:
            hash_ = self._node.type_hash(type_name)
        except SchemaError:
            return
        sub.token = self._session.declare_token(
            self._node.entity_key(
                rz.EntityKind.SUBSCRIPTION,
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
        self._routes.pop(sub.tag, None)
        self._samples.forget(topic)
        self.latched.forget(topic)
        self._pauses.forget(topic)
        if sub.handle is not None:
            self._session.undeclare(sub.handle)
        if sub.token is not None:
            self._session.undeclare(sub.token)

    # -- publishing ---------------------------------------------------------------------
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
        """A publisher (reliable or best effort) and its token, whose QoS says
        so; ``latch``: transient local, keeping the last ``queue_size``
        samples (1 by default) for late joiners (``_zenoh_latched``).
        ``queue_size`` is the depth the token announces (10 by default)."""
        if await self._pubs.reuse(topic, schema):
            return
        encode = self.codecs.encoder(schema, "cdr")
        key = self._node.key(topic, schema)
        depth = queue_size if queue_size is not None else (1 if latch else 10)
        qos = rz.Qos(reliable=not best_effort, transient_local=latch, depth=depth)
        token_key = self._node.entity_key(
            rz.EntityKind.PUBLISHER,
            name=topic,
            type_name=schema,
            hash_=rz.parse_key(key).type_hash,
            qos=qos,
        )
        if latch:
            publisher = self.latched.publisher(key, qos)
        else:
            publisher = self._session.declare_publisher(key, reliable=qos.reliable, express=False)
        token = self._session.declare_token(token_key)
        ready = anyio.Event()
        ready.set()
        self._pubs[topic] = _Publisher(
            schema, ready, topic, key, rz.entity_gid(token_key), encode, publisher, token
        )
        await self.descriptions.serve_descriptions()

    async def unadvertise(self, topic: str) -> None:
        pub = self._pubs.pop(topic, None)
        if pub is not None:
            self._session.undeclare(pub.token)
            with contextlib.suppress(Exception):
                pub.publisher.undeclare()

    def publishing(self) -> Mapping[str, str]:
        return self._pubs.schemas()

    def advertised(self, topic: str) -> str | None:
        return self._pubs.ready_schema(topic)

    def encode_publish(self, topic: str, data: Any) -> WireMessage:
        pub = self._pubs[topic]
        return TopicMessage(topic, pub.encode(data))

    async def send(self, message: WireMessage) -> None:
        if not isinstance(message, TopicMessage):
            raise TypeError("the zenoh adapter sends only TopicMessage")
        lost = self._node.lost
        if lost is not None or self._session.closed:
            raise ConnectError(f"zenoh: {lost or 'the session is closed'}")
        pub = self._pubs.get(message.topic)
        if pub is None:
            raise ConnectError(f"{message.topic} is no longer advertised on this session")
        pub.seq += 1
        attachment = rz.encode_attachment(pub.seq, time.time_ns(), pub.gid)
        try:
            pub.publisher.put(message.payload, attachment=attachment)
        except Exception as exc:  # a closed session
            raise ConnectError(f"zenoh: put failed: {exc}") from exc

    # -- calls ----------------------------------------------------------------------------
    async def call_service(self, name: str, request: Any, timeout: float) -> Any:
        srv_type = self._graph.service_type(name)
        if srv_type is None:
            raise ServiceError(name, "no server offers this service on this domain")
        await self.descriptions.describe_entity(name, rz.EntityKind.SERVICE)
        return await self._queries.request(name, srv_type, request, timeout)

    # -- lifecycle -----------------------------------------------------------------------------
    async def confirm_delivery(self) -> None:
        await self._queries.round_trip(self._options.teardown_timeout)

    def fail_pending(self, error: Exception) -> None:
        assert isinstance(error, RosBridgeError)
        self._queries.fail_all(error)
        self.actions.fail_all(error)

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
        while not self._session.closed and self._node.lost is None:
            await anyio.sleep(min(interval, 1.0))
            routers = await anyio.to_thread.run_sync(self._session.routers)
            if routers:
                missing_since = None
                self.actions.retry_results()
                start = time.perf_counter()
                if await self._queries.round_trip(self._options.keepalive_timeout):
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
        self.serving.close()
        await self._session.aclose()
