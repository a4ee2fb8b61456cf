"""The :class:`Client`: one API over every transport, the public front only.

Each method checks its arguments, then delegates: the connection's life
(tasks, reconnect, teardown with the zero Twist) is the
:class:`~._connection.Connection`'s, routing events to subscriptions is the
:class:`~._router.Router`'s, the wire format is the adapter's. The client
holds no wire format and starts no task of its own."""

from __future__ import annotations

import contextlib
from collections.abc import AsyncIterator, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from typing import TYPE_CHECKING, Any, TypeVar, overload

import anyio

from .._checks import (
    check_name,
    check_schema,
    check_timeout,
    check_uri,
    nearest_hint,
)
from .._errors import (
    ConnectError,
    MessageError,
    NotConnected,
    ParameterError,
    RosBridgeError,
)
from .._options import ClientOptions
from .._types import (
    Compression,
    ConnectionStats,
    Dispatch,
    PlaybackRequest,
    PlaybackState,
    Priority,
    SaveBandwidth,
    ServerInfo,
    ServerStatus,
    ServiceInfo,
    Status,
    StatusRemoved,
    TopicEndpoints,
    TopicInfo,
)
from ..adapters import ParameterAccess, require
from ..codec import FieldDef, same_type_name
from ..flow import FeedWatcher, Present, Watcher
from ..interfaces._base import RosGoal, RosMessage, RosRequest, RosService
from ._action import ActionGoal
from ._arguments import advertise_arguments, goal_arguments, publish_arguments, subscribe_arguments
from ._connection import Connection, SubscriptionContext, is_velocity_type, zero_twist
from ._published_types import PublishTypes
from ._serve import DEFAULT_SERVE_BUFFER, DEFAULT_SERVE_TIMEOUT, ServiceRequests

if TYPE_CHECKING:
    import os
    from typing import IO

    from ._record import Recording

__all__ = ["Client"]

T = TypeVar("T")
M = TypeVar("M", bound=RosMessage)
R = TypeVar("R", bound=RosMessage)
_Req = TypeVar("_Req", bound=RosMessage)
_Res = TypeVar("_Res", bound=RosMessage)
_Fb = TypeVar("_Fb", bound=RosMessage)


class Client:
    """A connection to one robot. Obtain it from :func:`ros_mobile_bridge.connect`.

    Every method that talks to the robot raises ``NotConnected`` when the
    connection is closed or lost, and validates its arguments before doing
    anything (``ValueError`` / ``TypeError``)."""

    def __init__(self, connection: Connection, options: ClientOptions) -> None:
        """(Internal: ``connect()`` builds the connection and runs its life.)"""
        self._options = options
        self._conn = connection
        self._router = connection.router
        self._types = PublishTypes(options.stop_topics)

    # -- lifecycle ----------------------------------------------------------
    @property
    def status(self) -> Status:
        """``"connected"``; ``"reconnecting"`` while a lost connection is
        being re-established (``options.reconnect``); ``"closed"`` after the
        block ends; ``"error"`` once the connection is lost for good (see
        :attr:`last_error`)."""
        return self._conn.status.value

    @property
    def last_error(self) -> BaseException | None:
        """Why the connection was lost, or None."""
        return self._conn.last_error

    def watch_status(self) -> Watcher[Status]:
        """Async iterator: the current status at once, then every change."""
        return self._conn.status.watch()

    @property
    def protocol(self) -> str:
        """The transport in use: ``"foxglove-ws"``, ``"rosbridge"`` or ``"zenoh"``."""
        return self._conn.adapter.protocol

    @property
    def server_info(self) -> ServerInfo:
        """What the server said about itself."""
        return self._conn.adapter.server_info

    @property
    def connected(self) -> bool:
        """True while the connection is up (``status == "connected"``)."""
        return self._conn.connected

    @property
    def rejections(self) -> dict[str, int]:
        """How many inbound frames were skipped or refused, per reason (a
        snapshot, counted over the client's life, across reconnects). Keys:
        ``"invalid_utf8"``, ``"malformed"``, ``"json_depth"``,
        ``"schema_too_large"``, ``"channel_limit"``, ``"service_limit"``,
        ``"fragment_limit"``; see the limits in :class:`ClientOptions`."""
        return self._router.rejections

    def stats(self) -> ConnectionStats:
        """What this client has read from the network, over its life and
        across reconnects: bytes (WebSocket framing included; over Zenoh the
        samples' payload bytes) and messages. Per subscription, see
        ``sub.stats.bytes_received``."""
        received, messages = self._conn.traffic()
        return ConnectionStats(bytes_received=received, messages_received=messages)

    # -- discovery ----------------------------------------------------------
    @property
    def topics(self) -> list[TopicInfo]:
        """The topics the server offers now."""
        return self._router.topics.value

    @property
    def services(self) -> list[ServiceInfo]:
        """The services the server offers now."""
        return self._router.services.value

    def watch_topics(self) -> Watcher[list[TopicInfo]]:
        """Async iterator: the topic list at once, then every change."""
        return self._router.topics.watch()

    def watch_services(self) -> Watcher[list[ServiceInfo]]:
        """Async iterator: the service list at once, then every change."""
        return self._router.services.watch()

    async def nodes(self) -> list[str]:
        """The ROS nodes of the robot's graph now: full names, sorted, this
        client's own node left out. Zenoh: the nodes' liveliness tokens;
        rosbridge: ``/rosapi/nodes`` (``ServiceError`` when the bridge has
        no rosapi); Foxglove: the ids in the server's connection graph
        (``NotSupportedError`` without its ``connectionGraph``). There is no
        node watch: the graph command (``rmb graph --watch``) polls this."""
        return await self._conn.offered("node_list").nodes()

    async def topic_endpoints(self, topic: str) -> TopicEndpoints:
        """Who publishes and subscribes to ``topic`` now, from the source :meth:`nodes`
        reads (rosbridge: ``/rosapi/publishers`` and ``/subscribers``); empty when unknown."""
        check_name("topic", topic)
        return await self._conn.offered("node_list").topic_endpoints(topic)

    async def wait_for_topic(self, topic: str, *, timeout: float | None = None) -> TopicInfo:
        """The topic's :class:`~ros_mobile_bridge.TopicInfo` once the robot
        offers ``topic`` (at once when it does already). ``TimeoutError``
        naming the nearest offered names when it did not within ``timeout``
        seconds (None: wait as long as it takes); ``NotConnected`` when the
        connection is lost for good (or closes) first. While the connection
        is being re-established it keeps waiting."""
        check_name("topic", topic)
        return await self._conn.wait_listed("topic", topic, self._router.topics.watch, timeout)

    async def wait_for_service(self, name: str, *, timeout: float | None = None) -> ServiceInfo:
        """The service's :class:`~ros_mobile_bridge.ServiceInfo` once the
        robot offers ``name``; as :meth:`wait_for_topic`, for services."""
        check_name("service name", name)
        return await self._conn.wait_listed("service", name, self._router.services.watch, timeout)

    # -- what a Foxglove server offers beside the graph (docs/transports) -----
    async def fetch_asset(self, uri: str, *, timeout: float | None = None) -> bytes:
        """The file the server offers as ``uri`` (``assets``: meshes, ``package://``
        URIs); ``AssetError`` with the server's reason, ``NotSupportedError``
        without assets, ``ServiceTimeout`` past ``timeout``."""
        check_uri(uri)
        return await self._conn.request(
            f"fetchAsset {uri}", lambda _: self._conn.offered("assets").fetch_asset(uri), timeout
        )

    @property
    def server_time(self) -> int | None:
        """The server's clock (ns) as it last sent it (Foxglove ``time``: a simulator's
        or a recording's clock); None before that, and over rosbridge and Zenoh."""
        return self._router.server_time.value

    def watch_server_time(self) -> Present[int]:
        """Async iterator: :attr:`server_time` at once when known, then the newest."""
        return Present(self._router.server_time)

    def watch_server_status(self) -> FeedWatcher[ServerStatus | StatusRemoved]:
        """Async iterator: each status the server sends or withdraws from now on
        (each also logged at its level); a reader 256 behind loses the oldest.
        Foxglove only: nothing arrives over rosbridge and Zenoh."""
        return self._router.server_status.watch()

    @property
    def playback_state(self) -> PlaybackState | None:
        """How the server plays its recording, as it last said (Foxglove
        ``playbackControl``); None before that, and over rosbridge and Zenoh."""
        return self._router.playback.value

    def watch_playback(self) -> Present[PlaybackState]:
        """Async iterator: :attr:`playback_state` at once when known, then the newest."""
        return Present(self._router.playback)

    async def control_playback(
        self, request: PlaybackRequest, *, timeout: float | None = None
    ) -> PlaybackState:
        """Play, pause, seek or change the speed of the recording the server
        plays; the state answering it. ``NotSupportedError`` without Foxglove's
        ``playbackControl``; ``ServiceTimeout`` when no answer came within ``timeout``."""
        if not isinstance(request, PlaybackRequest):
            raise TypeError(f"request must be a PlaybackRequest, not {type(request).__name__}")
        return await self._conn.request(
            "playbackControlRequest",
            lambda _: self._conn.offered("playback").control_playback(request),
            timeout,
        )

    # -- subscriptions ------------------------------------------------------
    @overload
    def subscribe(
        self,
        topic: str,
        type: type[M],
        *,
        max_hz: float | None = None,
        adaptive: bool = True,
        dispatch: Dispatch = "all",
        schema: str | None = None,
        buffer: int | None = None,
        compression: Compression | None = None,
        decode: bool = True,
        save_bandwidth: SaveBandwidth = False,
    ) -> SubscriptionContext[M]: ...

    @overload
    def subscribe(
        self,
        topic: str,
        type: str | None = None,
        *,
        max_hz: float | None = None,
        adaptive: bool = True,
        dispatch: Dispatch = "all",
        schema: str | None = None,
        buffer: int | None = None,
        compression: Compression | None = None,
        decode: bool = True,
        save_bandwidth: SaveBandwidth = False,
    ) -> SubscriptionContext[Any]: ...

    def subscribe(
        self,
        topic: str,
        type: type[RosMessage] | str | None = None,
        *,
        max_hz: float | None = None,
        adaptive: bool = True,
        dispatch: Dispatch = "all",
        schema: str | None = None,
        buffer: int | None = None,
        compression: Compression | None = None,
        decode: bool = True,
        save_bandwidth: SaveBandwidth = False,
    ) -> SubscriptionContext[Any]:
        """Subscribe to ``topic``; an async context manager yielding a
        :class:`~ros_mobile_bridge.Subscription` (``async for msg in sub``).

        ``type``: the message class (``subscribe("/odom", Odometry)``) or
        type name (``"nav_msgs/msg/Odometry"``) of the topic, when the
        caller knows it (``schema=`` is the same as a name). With a class,
        the subscription is a ``Subscription[Odometry]``: ``msg.data`` is
        an ``Odometry`` for type checkers and at run time; a message whose
        definition on the robot differs from the class's is delivered raw,
        its ``decode_error`` saying so. Without one, ``msg.data`` is still
        an instance of the type's class whenever the library knows the
        type's ROS definition (see :class:`~ros_mobile_bridge.Message`).

        The topic need not be advertised yet: the subscription stays
        ``pending`` and becomes ``active`` when the server offers it.
        ``max_hz`` caps the delivery rate (frames in between are dropped
        before decoding; the newest one is delivered at the end of the
        window). Over Foxglove, while every subscription of the connection
        is inside its window, the socket is not read until the earliest
        window ends (then what came meanwhile is read together, and the
        newest delivered), unless a request waits for its answer or a
        window's messages would exceed 64 KiB (see "Subscriptions" in the
        concepts page). ``adaptive`` lets the event loop's lag widen that interval
        (``options.throttle_mode``); the effective interval is the larger of
        the two, and a subscription with ``adaptive=False`` ignores the lag
        (and its breaker never trips on its own). ``dispatch="latest"`` keeps only the newest undelivered
        message; ``"all"`` queues up to ``buffer`` and drops the oldest when
        the consumer falls behind. ``compression`` (rosbridge only, ignored
        elsewhere): ``"cbor"`` or ``"cbor-raw"`` (CDR, decoded here) instead
        of JSON; images are far smaller and cheaper to decode.

        ``decode=False`` delivers each payload as it arrived: ``Message.data``
        is a ``memoryview`` of the wire bytes (CDR over Foxglove and Zenoh,
        the JSON or CBOR text of the ``publish`` op over rosbridge) and
        ``byte_size`` its length; the codec is never called for a message
        (the adapter may still prepare a decoder for the topic's type), so
        ``decode_error`` is always None and ``stats.decode_failures`` stays
        0. ``max_hz``, ``adaptive``, ``dispatch``, ``buffer`` and the
        breaker apply exactly as for decoded messages: a counter of every
        frame (``rmb hz``) passes ``adaptive=False`` and no ``max_hz``, and
        reads ``stats.received`` (every frame routed to the subscription,
        counted before any filter) rather than the messages delivered, so
        frames the buffer drops under load are still counted.

        ``save_bandwidth`` (Foxglove; needs ``max_hz``): the Foxglove
        protocol has no rate option, so by default the server sends every
        message and ``max_hz`` saves CPU, not bytes. With
        ``save_bandwidth=True`` the client unsubscribes from the channel
        after each message it takes and subscribes again when the next one
        is due on the ``max_hz`` schedule, so the server sends about one
        message per interval (``"adaptive"``: the adaptive throttle's
        interval too, when it is longer; then ``max_hz`` may be None). The
        price: a message published while the stream is paused is never
        seen, so when a topic stops, its last message can be missed (the
        default mode always delivers it), and a delivery waits for the first
        message published after the resubscription (which is made as much
        ahead of time as that wait took lately). A message the
        server replays to the new subscription (a transient-local topic)
        that is byte for byte the one delivered last is skipped and
        counted in ``stats.dropped_replay`` (only the first message after
        each resubscription is checked, so a topic whose messages are all
        alike loses one per resubscription, never the stream). On Zenoh
        the subscriber is undeclared and declared again the same way (no
        replay there). rosbridge accepts the mode and changes nothing
        (``max_hz`` already reaches it as ``throttle_rate``). Several
        subscriptions to one topic pause only when every one asks for it.
        Arguments are checked here, at once."""
        check_name("topic", topic)
        want, schema, mode = subscribe_arguments(
            type, schema, compression, adaptive, decode, save_bandwidth, max_hz
        )
        route = self._router.route(
            topic,
            max_hz=max_hz,
            adaptive=adaptive,
            dispatch=dispatch,
            schema=schema,
            buffer=buffer,
            compression=compression,
            decode=decode,
            save_bandwidth=mode,
            want=want,
        )
        return SubscriptionContext(self._conn, route)

    # -- publishing ---------------------------------------------------------
    async def advertise(
        self,
        topic: str,
        schema: str,
        *,
        latch: bool = False,
        queue_size: int | None = None,
        best_effort: bool = False,
    ) -> None:
        """Advertise ``topic`` as ``schema`` before the first publish. ``latch``: keep
        the last ``queue_size`` messages (1) for late subscribers (rosbridge, Zenoh);
        ``best_effort`` (Zenoh). ``NotSupportedError`` where the protocol cannot."""
        options = advertise_arguments(topic, schema, latch, queue_size, best_effort)
        await self._conn.advertise(topic, schema, options)

    async def unadvertise(self, topic: str) -> None:
        """Stop publishing ``topic``. A velocity topic still gets its zero
        Twist on teardown."""
        check_name("topic", topic)
        await self._conn.unadvertise(topic)

    @overload
    async def publish(
        self,
        topic: str,
        schema: RosMessage,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
    ) -> None: ...

    @overload
    async def publish(
        self,
        topic: str,
        schema: str,
        data: Mapping[str, Any] | RosMessage,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
    ) -> None: ...

    async def publish(
        self,
        topic: str,
        schema: str | RosMessage,
        data: Mapping[str, Any] | RosMessage | None = None,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
    ) -> None:
        """Publish a message on ``topic``: ``publish("/cmd_vel", Twist(...))``
        takes the type from the instance; ``publish(topic, schema, data)``
        names the type and gives a dict (missing fields are zero) or an
        instance of the type's class.

        Before anything is advertised or sent, the type is checked and a
        mistake raises :class:`~ros_mobile_bridge.SchemaError` naming it: a
        type with no definition (none bundled, none from the server - a
        channel's schema, the graph's topic types, rosbridge's
        ``/rosapi/message_details`` - and none given to
        :meth:`register_type`); a type that contradicts the one the graph
        reports for ``topic`` (:attr:`topics`); anything but
        ``geometry_msgs/msg/Twist`` or ``TwistStamped`` on a velocity topic
        (a name ending in ``cmd_vel``, or one in ``options.stop_topics``)
        unless ``check_velocity=False``.

        The first publish on a topic advertises it (and waits
        ``options.advertise_settle``). ``priority="control"`` puts the frame
        in the control outbox: it leaves ahead of every queued data frame,
        and a newer control value for the same topic replaces an unsent one.
        ``"data"`` frames queue in order (this waits while 1024 are queued).
        A data frame returns once queued. A control frame returns once it
        (or a newer value for the same topic that replaced it) is written to
        the socket, and raises ``NotConnected`` with the reason when it was
        not: the connection was lost first (a peer that stops reading is
        detected within ``keepalive_interval + keepalive_timeout``), or the
        client closed. It never returns for a frame that was not written.
        :class:`~ros_mobile_bridge.MessageError` (a ``ValueError``) naming
        the field when ``data`` does not fit the schema."""
        check_name("topic", topic)
        schema, data = publish_arguments(schema, data)
        check_schema(schema)
        if priority not in ("data", "control"):
            raise ValueError(f"priority must be 'data' or 'control', got {priority!r}")
        if not isinstance(check_velocity, bool):
            raise TypeError("check_velocity must be a bool")
        self._conn.require_connected()
        conn = self._conn
        adapter = conn.adapter
        velocity = is_velocity_type(schema)
        await self._types.check(
            adapter, self._router.topics.value, topic, schema, check_velocity, velocity
        )
        ready = adapter.advertised(topic)
        if ready is None or not same_type_name(ready, schema):
            await adapter.advertise(topic, schema)  # the hot path skips this await
        try:
            message = adapter.encode_publish(topic, data)
        except MessageError as exc:  # the call's name is built only here, off the hot path
            raise exc.in_call(f"publish {topic}") from None
        if velocity:
            conn.velocity[topic] = schema
        if priority == "control":
            error = await conn.outbound.publish_control(topic, message)
            if error is not None:
                raise NotConnected(
                    f"disconnected: {error} (the control frame for {topic} was not sent)"
                ) from error
        else:
            await conn.outbound.outbox.put_data(topic, message)

    def register_type(
        self, name: str, definition: str | bytes, *, encoding: str = "ros2msg"
    ) -> None:
        """Make message type ``name`` known to this client (and to every
        connection it re-opens), for publishing a type that is neither
        bundled nor offered by the server, and for :meth:`schema_template`.

        ``definition`` is ``.msg`` text (``encoding="ros2msg"``; nested types
        it uses must be bundled, registered before, or appended in the
        concatenated ``=====`` / ``MSG: pkg/msg/Type`` form), IDL text
        (``"ros2idl"``), a ``.srv`` text for ``pkg/srv/X`` (``"ros2msg"``:
        registers ``X_Request`` and ``X_Response``), or an ``.action`` text
        for ``pkg/action/X`` (``"ros2action"``: registers the goal, result,
        feedback and the send-goal / get-result types ROS derives from it;
        Zenoh needs them to send goals). It is checked at once:
        ``SchemaError`` when it does not parse or uses an unknown type,
        ``ValueError`` / ``TypeError`` for bad arguments. A server's own
        definition of the same name wins for the messages it sends."""
        self._types.register(name, definition, encoding)
        self._types.apply(self._conn.adapter)

    async def fetch_definition(self, name: str) -> bool:
        """Whether a definition of message type ``name`` is known now, after
        asking the server for one where its protocol can (rosbridge:
        ``/rosapi/message_details``; Zenoh: the type description service of
        a node that uses it; Foxglove sends definitions only with its
        channels, so there it only checks what is known). ``NotConnected``
        when the connection is not up."""
        check_schema(name)
        self._conn.require_connected()
        adapter = self._conn.adapter
        if adapter.descriptions is None:
            return adapter.codecs.resolves(name)
        return await adapter.descriptions.fetch_definition(name)

    async def publish_zero_twist(self, topic: str = "/cmd_vel", schema: str | None = None) -> None:
        """Publish a zero velocity at control priority. ``schema`` defaults to
        what this client already published there, else the advertised type,
        else ``geometry_msgs/msg/Twist``."""
        check_name("topic", topic)
        if schema is None:
            schema = self._conn.velocity_schema(topic)
        elif not is_velocity_type(check_schema(schema)):
            raise ValueError(f"schema must be Twist or TwistStamped, got {schema!r}")
        await self.publish(topic, schema, zero_twist(schema), priority="control")

    async def confirm_delivery(self, *, timeout: float | None = None) -> None:
        """Return once everything published so far (data frames queued
        included) has reached the bridge, as a round trip behind it shows
        (Foxglove: a WebSocket ping; rosbridge: rosapi's ``get_time``). Over
        Zenoh it raises ``NotSupportedError``: a put has no acknowledgement
        and no query only the router answers proves it has one. Raises
        ``NotConnected`` when the connection is lost first (what was sent
        may or may not have arrived: a write into a socket whose peer just
        died returns normally, TCP cannot tell), ``ServiceTimeout`` after
        ``timeout`` (default ``options.service_timeout``). The server having
        a message is not the robot acting on it; a robot that must stop
        when commands stop needs its own ``cmd_vel`` watchdog."""
        await self._conn.confirm_delivery(check_timeout(timeout))

    # -- recording ----------------------------------------------------------
    def record(
        self,
        path: str | os.PathLike[str] | IO[bytes],
        *,
        topics: Sequence[str] | None = None,
        max_hz: float | None = None,
        adaptive: bool = True,
        compression: Compression | None = None,
    ) -> AbstractAsyncContextManager[Recording]:
        """Record what this client receives to the MCAP file ``path``; an
        async context manager yielding a :class:`~ros_mobile_bridge.Recording`
        (``rec.stats``)::

            async with robot.record("run.mcap", topics=["/odom", "/scan"]) as rec:
                await anyio.sleep(10)
            print(rec.stats.messages)

        ``topics`` None records every topic the server offers, and those it
        offers later. Each topic is an ordinary subscription (``max_hz``, the
        adaptive throttle unless ``adaptive=False``, and the circuit breaker
        apply as to any other); the
        file holds ROS 2 CDR messages with their full ``ros2msg`` schemas,
        from any transport (rosbridge's JSON is encoded to CDR with the
        connection's codec; ``compression="cbor-raw"`` has the bridge send
        CDR instead). Leaving the block finishes the file (summary and
        indexes), on every exit path, cancellation included. Needs the
        ``mcap`` package (the ``[record]`` extra). Arguments are checked
        here, at once (``ValueError`` / ``TypeError``); the file is created
        (or truncated) on entering (``OSError``). ``path`` may also be a
        binary stream (``sys.stdout.buffer``), written, flushed and left
        open. See docs/recording.md."""
        from ._record import check_record_args, open_recording

        checked, wanted = check_record_args(path, topics, max_hz, compression)
        if not isinstance(adaptive, bool):
            raise TypeError("adaptive must be a bool")
        return open_recording(self._conn, checked, wanted, max_hz, adaptive, compression)

    # -- services -----------------------------------------------------------
    @overload
    async def call_service(
        self, name: str, request: RosRequest[R], *, timeout: float | None = None
    ) -> R: ...

    @overload
    async def call_service(
        self,
        name: str,
        request: Mapping[str, Any] | RosMessage | None = None,
        *,
        timeout: float | None = None,
    ) -> Any: ...

    async def call_service(
        self,
        name: str,
        request: Mapping[str, Any] | RosMessage | None = None,
        *,
        timeout: float | None = None,
    ) -> Any:
        """Call service ``name`` with ``request`` and return the response.

        ``request`` is an instance of the service's request class
        (``AddTwoInts.Request(a=1, b=2)``; then type checkers know the call
        returns an ``AddTwoInts.Response``) or a dict (missing fields are
        zero). The response is an instance of the response class whenever
        the library knows the service type's definition, else a dict.

        Raises :class:`~ros_mobile_bridge.MessageError` naming the field,
        before anything is sent, when ``request`` does not fit the request
        type (where the type is known); ``ServiceError`` with the server's
        text when the call fails, ``ServiceTimeout`` when no answer came
        within ``timeout`` seconds (default ``options.service_timeout``),
        ``NotConnected`` when the connection is or goes away. A call never
        waits forever."""
        check_name("service name", name)
        if request is not None and not isinstance(request, Mapping | RosMessage):
            raise TypeError(
                "request must be a message instance, a mapping (dict) or None, "
                f"not {type(request).__name__}"
            )
        adapter = self._conn.adapter
        try:
            return await self._conn.request(
                name,
                lambda limit: adapter.call_service(name, request, limit),
                timeout,
                slack=adapter.wire_timeout_slack,
            )
        except MessageError as exc:
            raise exc.in_call(f"call_service {name}") from None

    @overload
    def serve(
        self,
        name: str,
        service_type: type[RosService[_Req, R]],
        *,
        timeout: float = ...,
        buffer: int = ...,
    ) -> AbstractAsyncContextManager[ServiceRequests[_Req, R]]: ...
    @overload
    def serve(
        self, name: str, service_type: str, *, timeout: float = ..., buffer: int = ...
    ) -> AbstractAsyncContextManager[ServiceRequests]: ...
    def serve(
        self,
        name: str,
        service_type: str | type[RosService[Any, Any]],
        *,
        timeout: float = DEFAULT_SERVE_TIMEOUT,
        buffer: int = DEFAULT_SERVE_BUFFER,
    ) -> AbstractAsyncContextManager[ServiceRequests[Any, Any]]:
        """Offer service ``name`` of type ``service_type`` (the service's
        class, ``AddTwoInts``, or its name, ``"pkg/srv/Name"``) to the ROS
        graph through the bridge; an async context manager yielding
        :class:`~ros_mobile_bridge.ServiceRequests`::

            async with robot.serve("/add", AddTwoInts) as requests:
                async for req in requests:  # req.args: an AddTwoInts.Request
                    await req.reply(AddTwoInts.Response(sum=req.args.a + req.args.b))

        Every call is answered exactly once: by ``req.reply(values)`` or
        ``req.fail(message)``, else with ``result: false`` and a reason when
        ``timeout`` seconds pass, when the loop moves on to the next request,
        or when the block ends; a call arriving while ``buffer`` unread ones
        wait is refused at once (``stats.overflowed``). Leaving the block
        unadvertises the service (shielded, within
        ``options.teardown_timeout``). After a reconnect it is advertised
        again; calls that were in flight on the lost connection are lost.

        Over rosbridge and Zenoh; ``NotSupportedError`` over Foxglove (its
        protocol has no way to offer a service). Arguments are checked here, at
        once (``ValueError`` / ``TypeError``); entering raises
        ``SchemaError`` when the bridge does not know the type,
        ``ServiceError`` when another client serves the name, ``ValueError``
        when this client serves it already."""
        check_name("service name", name)
        if isinstance(service_type, type) and issubclass(service_type, RosService):
            service_type = service_type.__ros_type__
        check_schema(service_type)
        if service_type.count("/") == 2 and service_type.split("/")[1] != "srv":
            raise ValueError(
                f"service_type must be a service type like 'pkg/srv/Name', got {service_type!r}"
            )
        limit = check_timeout(timeout)
        if limit is None:
            raise TypeError("timeout must be a number of seconds")
        if isinstance(buffer, bool) or not isinstance(buffer, int):
            raise TypeError("buffer must be an int")
        if buffer < 1:
            raise ValueError(f"buffer must be at least 1, got {buffer}")
        return self._serve(name, service_type, limit, buffer)

    @asynccontextmanager
    async def _serve(
        self, name: str, service_type: str, timeout: float, buffer: int
    ) -> AsyncIterator[ServiceRequests]:
        conn = self._conn
        conn.require_connected()
        require(conn.adapter.serving, "serving", conn.adapter.protocol)
        async with conn.served.serve(
            name, service_type, timeout, buffer, conn.current_host
        ) as served:
            yield served

    # -- parameters ---------------------------------------------------------
    def _parameters(self) -> ParameterAccess:
        """The connection's parameter part (``NotSupportedError`` when it has none)."""
        adapter = self._conn.adapter
        return require(adapter.parameters, "parameters", adapter.protocol)

    async def get_parameters(
        self, names: Sequence[str], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Current values of the named parameters (over Zenoh and rosbridge
        written ``/node:param``).

        :class:`~ros_mobile_bridge.ParameterError` when the robot does not
        have some of them: ``exc.reasons`` maps each missing name to
        ``"not found"`` with the nearest names the robot has, ``exc.values``
        holds the values of the names it has. ``NotSupportedError`` when the
        server offers no parameters, ``ServiceTimeout`` past ``timeout``."""
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise TypeError("names must be a sequence of str")
        names = list(names)
        values = await self._conn.request(
            "getParameters", lambda _limit: self._parameters().get_parameters(names), timeout
        )
        missing = [n for n in names if n not in values]
        if missing:
            raise ParameterError(await self._not_found(missing, timeout), values)
        return values

    async def _not_found(self, names: Sequence[str], timeout: float | None) -> dict[str, str]:
        """``"not found"`` for each of ``names``, with the nearest names the
        robot has (one listing; none when it cannot be had)."""
        try:
            known = sorted(await self.list_parameters(timeout=timeout))
        except RosBridgeError:
            known = []
        return {name: "not found" + nearest_hint(name, known) for name in names}

    async def list_parameters(self, *, timeout: float | None = None) -> dict[str, Any]:
        """Every parameter the server exposes, with its value."""
        return await self._conn.request(
            "getParameters", lambda _limit: self._parameters().get_parameters([]), timeout
        )

    async def set_parameters(
        self, values: Mapping[str, Any], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Set parameters; returns the values the robot reports afterwards,
        each as it was sent.

        When the robot refuses some of them (a value of the wrong type, out
        of range, a read-only parameter) or does not have them, every value
        it accepted is applied, and then
        :class:`~ros_mobile_bridge.ParameterError` is raised:
        ``exc.reasons`` maps each failed name to the robot's reason (rcl's
        ``SetParametersResult.reason`` over Zenoh and rosbridge; over
        Foxglove, whose protocol has none, the value the robot kept), and
        ``exc.values`` holds what the robot reports afterwards. A call never
        returns with a value not taken. ``NotSupportedError`` when the server
        offers no parameters, ``ServiceTimeout`` past ``timeout``."""
        if not isinstance(values, Mapping) or not all(isinstance(k, str) for k in values):
            raise TypeError("values must be a mapping of parameter name to value")
        values = dict(values)
        reasons: dict[str, str] = {}
        try:
            after = await self._conn.request(
                "setParameters", lambda _limit: self._parameters().set_parameters(values), timeout
            )
        except ParameterError as exc:
            after, reasons = exc.values, exc.reasons
        missing = [
            n for n, v in values.items() if n not in after and n not in reasons and v is not None
        ]
        if missing:
            reasons.update(await self._not_found(missing, timeout))
        if reasons:
            raise ParameterError(reasons, after)
        return after

    @asynccontextmanager
    async def watch_parameters(
        self, names: Sequence[str]
    ) -> AsyncIterator[AsyncIterator[dict[str, Any]]]:
        """Subscribe to updates of the named parameters. Yields an async
        iterator of ``{name: value}`` snapshots (the newest known values of
        the watched names), one per change."""
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise TypeError("names must be a sequence of str")
        wanted = list(names)
        self._conn.require_connected()
        parameters = self._router.parameters

        async def updates() -> AsyncIterator[dict[str, Any]]:
            last: dict[str, Any] | None = None
            async for snapshot in parameters.watch():
                view = {n: snapshot[n] for n in wanted if n in snapshot}
                if view and view != last:
                    last = view
                    yield view

        async with self._router.watch_parameters(wanted):
            iterator = updates()
            try:
                yield iterator
            finally:
                with (
                    anyio.CancelScope(shield=True),
                    anyio.move_on_after(self._options.teardown_timeout),
                ):
                    await iterator.aclose()  # type: ignore[attr-defined]

    # -- schemas ------------------------------------------------------------
    def schema_template(self, name: str) -> dict[str, Any]:
        """A zero-filled message of type ``name`` (fixed-size arrays filled),
        from the server's schemas or the bundled ROS 2 definitions."""
        return self._conn.adapter.codecs.template(check_schema(name))

    def schema_definition(self, name: str) -> list[FieldDef]:
        """The fields of type ``name``, in order, with their types."""
        return self._conn.adapter.codecs.definition(check_schema(name))

    # -- actions ------------------------------------------------------------
    @overload
    def send_action_goal(
        self, action: str, action_type: RosGoal[_Res, _Fb]
    ) -> AbstractAsyncContextManager[ActionGoal[_Res, _Fb]]: ...

    @overload
    def send_action_goal(
        self, action: str, action_type: str, goal: Mapping[str, Any] | RosMessage
    ) -> AbstractAsyncContextManager[ActionGoal[Any, Any]]: ...

    @asynccontextmanager
    async def send_action_goal(
        self,
        action: str,
        action_type: str | RosGoal[Any, Any],
        goal: Mapping[str, Any] | RosMessage | None = None,
    ) -> AsyncIterator[ActionGoal[Any, Any]]:
        """Send a goal to action server ``action``; an async context manager
        yielding the :class:`~ros_mobile_bridge.ActionGoal`.
        ``send_action_goal("/fibonacci", Fibonacci.Goal(order=5))`` takes the
        action type from the goal's class (and type checkers know the
        goal's result is a ``Fibonacci.Result``, its feedback a
        ``Fibonacci.Feedback``); ``send_action_goal(action, action_type,
        goal)`` names the type (``"example_interfaces/action/Fibonacci"``)
        and gives a dict (missing fields are zero) or a goal instance. The
        feedback and the result are instances of the action's classes
        whenever the library knows its definition, else dicts.

        Leaving the block before the goal ended cancels it (shielded, within
        ``options.teardown_timeout``). A lost connection fails the goal with
        reason ``"disconnected"``. ``NotSupportedError`` over Foxglove, whose
        protocol has no actions; :class:`~ros_mobile_bridge.MessageError`
        naming the field, before anything is sent, when ``goal`` does not
        fit the goal type; ``ActionGoalError`` when no server offers the
        action or it refuses the goal."""
        check_name("action", action)
        action_type, goal = goal_arguments(action_type, goal)
        check_schema(action_type)
        conn = self._conn
        conn.require_connected()
        adapter = conn.adapter
        actions = require(adapter.actions, "actions", adapter.protocol)
        goal_id: list[str] = []

        async def cancel() -> None:
            if goal_id and conn.current() is adapter:
                await actions.cancel_action_goal(action, goal_id[0])

        handle = ActionGoal(action, cancel)
        try:
            goal_id.append(await actions.send_action_goal(action, action_type, goal, handle))
        except MessageError as exc:
            raise exc.in_call(f"send_action_goal {action}") from None
        try:
            yield handle
        finally:
            if not handle.done:
                with (
                    anyio.CancelScope(shield=True),
                    anyio.move_on_after(self._options.teardown_timeout),
                    contextlib.suppress(ConnectError, NotConnected),
                ):
                    await handle.cancel()
