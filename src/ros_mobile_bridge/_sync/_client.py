"""``connect_sync()``: the client for code that is not async.

One worker thread runs an event loop (asyncio or trio) with an anyio
:class:`~anyio.from_thread.BlockingPortal`; the async :class:`Client` lives
there, and every blocking method hands one coroutine to the loop and waits
for its result. An ``async with`` the worker holds (the connection, a
subscription, an action goal) is entered and left by one task of the
worker, so anyio's cancel scopes stay in the task that opened them.

Every blocking wait ends with the call's result, its error, the caller's
``timeout`` (``TimeoutError``), a ``KeyboardInterrupt`` in the waiting
thread (which cancels the call in the loop), or ``NotConnected`` when the
client is closed or the worker thread has stopped (every call still waiting
is failed as the thread ends). Not every wait has a bound of its own: see
:class:`SyncClient` for which ones wait until one of those happens."""

from __future__ import annotations

import atexit
import inspect
import logging
import threading
import time
from collections.abc import Awaitable, Callable, Mapping, Sequence
from contextlib import AbstractAsyncContextManager
from types import TracebackType
from typing import TYPE_CHECKING, Any, TypeVar, overload

from .._checks import check_timeout as _check_timeout
from .._connect import ProtocolArg, connect
from .._core._client import Client
from .._errors import NotConnected
from .._loop._backends import Backend, run_args
from .._options import CLOSE_SLACK_S, ClientOptions
from .._types import (
    Compression,
    ConnectionStats,
    Dispatch,
    PlaybackRequest,
    PlaybackState,
    Priority,
    SaveBandwidth,
    ServerInfo,
    ServiceInfo,
    Status,
    TopicEndpoints,
    TopicInfo,
)
from ..codec import FieldDef
from ..flow import Subscription
from ..interfaces._base import RosGoal, RosMessage, RosRequest
from ._blocks import SyncActionGoal, SyncSubscription
from ._worker import JOIN_S, Children, Held, Parent, Worker

if TYPE_CHECKING:
    pass

__all__ = ["SyncActionGoal", "SyncClient", "SyncSubscription", "connect_sync"]

T = TypeVar("T")
T_ = TypeVar("T_")
_M = TypeVar("_M", bound=RosMessage)
_R = TypeVar("_R", bound=RosMessage)
_Res = TypeVar("_Res", bound=RosMessage)
_Fb = TypeVar("_Fb", bound=RosMessage)
F = TypeVar("F", bound=Callable[..., Any])


def _mirrors(sync: F) -> F:
    """Carry the docstring of :class:`Client`'s namesake of ``sync`` (a
    method, or a property's getter) into ``sync``'s, at import: the async
    text, then ``sync``'s own note (what differs when blocking). The own
    note is what static readers (the API reference, IDEs) show, so it names
    the async member. Nothing is carried while ``Client`` has no such name.
    ``tests/test_sync_surface.py`` checks that every mirror carries it."""
    original = getattr(Client, sync.__name__, None)
    text = None if original is None else original.__doc__
    if text and sync.__doc__:
        sync.__doc__ = f"{inspect.cleandoc(text)}\n\n{inspect.cleandoc(sync.__doc__)}"
    return sync


# Sync clients still open at interpreter exit are closed (teardown included)
# by this hook; the daemon worker threads would otherwise just stop. Each
# maps to the logger of the options it was connected with.
_open_clients: dict[SyncClient, logging.Logger] = {}


@atexit.register
def _close_at_exit() -> None:
    for client, log in list(_open_clients.items()):
        try:
            client.close()
        except Exception as exc:  # the next client must still be closed
            log.warning("closing %r at interpreter exit failed: %r", client, exc)


def connect_sync(
    target: str,
    *,
    protocol: ProtocolArg = "auto",
    port: int | None = None,
    secure: bool | None = None,
    options: ClientOptions | None = None,
    backend: Backend = "asyncio",
    backend_options: Mapping[str, Any] | None = None,
) -> SyncClient:
    """Connect from code that is not async (scripts, notebooks, test
    harnesses); returns a :class:`SyncClient`, connected, whose methods
    block::

        with rmb.connect_sync("robot.local") as robot:
            robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.2}})
            with robot.subscribe("/odom", timeout=5) as sub:
                msg = sub.get()
        # the block's end sent the zero Twist and stopped the worker thread

    ``target``, ``protocol``, ``port``, ``secure`` and ``options`` are
    :func:`~ros_mobile_bridge.connect`'s, plus ``backend`` (``"asyncio"``,
    ``"trio"``, or ``"uvloop"``: asyncio on uvloop, the ``[uvloop]`` extra)
    and ``backend_options`` (:func:`anyio.run`'s) for the event loop of the
    worker thread the client runs in. It raises what
    ``connect()`` raises (``ValueError``, ``ConnectError``, ...), with the
    worker already stopped.

    Use it as a context manager, or call :meth:`SyncClient.close`: both run
    the async teardown (the zero Twist to every velocity topic published
    to) and join the thread. A ``KeyboardInterrupt`` in a blocking call
    cancels that call; leaving the ``with`` block then closes as usual. A
    client still open at interpreter exit is closed by an ``atexit`` hook."""
    if backend_options is not None and not isinstance(backend_options, Mapping):
        raise TypeError("backend_options must be a mapping or None")
    # the loop's package is asked for before a loop starts
    loop, loop_options = run_args(backend, backend_options, f"connect_sync(backend={backend!r})")
    if options is not None and not isinstance(options, ClientOptions):
        raise TypeError("options must be a ClientOptions")
    cm = connect(target, protocol=protocol, port=port, secure=secure, options=options)
    opts = options or ClientOptions()
    worker = Worker(loop, loop_options, f"rmb-sync-{backend}", opts.logger)
    held = Held(worker, cm, "the connection")
    try:
        client = held.enter()
    except BaseException:
        worker.stop(JOIN_S)
        raise
    return SyncClient(worker, held, client, opts.teardown_timeout, opts.logger)


class SyncClient:
    """A connected client whose methods block: :func:`connect_sync` returns it.

    It mirrors :class:`~ros_mobile_bridge.Client`; each method runs the
    async one in the worker thread's event loop and returns its result or
    raises its error. Methods that talk to the robot take an optional
    ``timeout`` (seconds; ``TimeoutError`` when it passes, the call is then
    cancelled); without one they wait as the async method does:

    * bounded by options: :func:`connect_sync` (``connect_timeout``),
      :meth:`call_service` and the parameter calls (``service_timeout``),
      :meth:`close` (``teardown_timeout`` + 5 s, plus up to 5 s to join
      the thread);
    * waiting on local progress (the outbox, the socket), which a lost
      connection fails: :meth:`publish`, :meth:`publish_zero_twist`,
      :meth:`advertise`, :meth:`unadvertise`, :meth:`SyncActionGoal.cancel`
      (on zenoh a request bounded by ``service_timeout``);
    * waiting for the robot to do something it may never do, so without a
      ``timeout`` they wait until it does, the subscription or goal ends,
      the connection is lost (for a subscription: for good, as it survives
      a reconnect), :meth:`close` is called from another thread, or
      ``KeyboardInterrupt``: :meth:`SyncSubscription.get`,
      ``next(sub)``, :meth:`SyncSubscription.get_batch` and
      :meth:`SyncSubscription.wait_active` (their default is the
      ``timeout`` given to :meth:`subscribe`, None unless given),
      :meth:`SyncActionGoal.accepted`, :meth:`SyncActionGoal.result`,
      :meth:`SyncActionGoal.next_feedback`, and :meth:`run` (as long as
      ``fn`` runs), :meth:`wait_for_topic` and :meth:`wait_for_service`.

    Once the worker thread has stopped, or after :meth:`close`, they raise
    ``NotConnected``.

    Several threads may call one SyncClient at once: each call is its own
    task in the worker's event loop (a :class:`SyncSubscription` is meant
    for one consuming thread)."""

    def __init__(
        self,
        worker: Worker,
        held: Held[Client],
        client: Client,
        teardown_timeout: float,
        log: logging.Logger,
    ) -> None:
        self._worker = worker
        self._held = held
        self._client = client
        self._teardown_timeout = teardown_timeout
        self._log = log
        self._children = Children()  # entered subscriptions and goals, left by close()
        self._parent = Parent(worker, self._children, teardown_timeout + CLOSE_SLACK_S)
        self._closed = False
        self._close_lock = threading.Lock()
        _open_clients[self] = log

    # -- lifecycle ----------------------------------------------------------
    def __enter__(self) -> SyncClient:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"<SyncClient {self._client.protocol} {self.status} ({self._worker.thread.name})>"

    def close(self, timeout: float | None = None) -> None:
        """Close: leave the open subscriptions and action goals, run the
        client's teardown (control frames flushed, the zero Twist to every
        velocity topic this client published to and to
        ``options.stop_topics``, the socket closed), stop the event loop and
        join the worker thread. ``timeout`` bounds the wait for all that
        (default ``options.teardown_timeout`` + 5 s), except that joining
        the thread may take up to 5 s of its own; past it the thread is left
        to end on its own and a warning is logged. Idempotent; safe to call
        from any thread but the worker's.

        A bad ``timeout`` (``TypeError``, or ``ValueError`` unless a
        positive finite number) or a call from the worker's own loop
        (``RuntimeError``, inside :meth:`run`) raises at once and leaves the
        client open: a later ``close()`` still closes it. Once closing has
        begun it always ends with the loop stopped, whatever is raised on
        the way (a second Ctrl-C included)."""
        limit = _check_timeout(timeout)
        if threading.get_ident() == self._worker.thread.ident:
            raise RuntimeError(
                "SyncClient.close() was called from its own event loop (inside "
                "SyncClient.run): close it from another thread, after run() returns"
            )
        deadline = _now() + (self._teardown_timeout + CLOSE_SLACK_S if limit is None else limit)
        with self._close_lock:
            if self._closed:
                return
            self._closed = True
        try:
            _open_clients.pop(self, None)
            for child in self._children.entered():
                try:
                    self._children.leave(child, max(0.0, deadline - _now()))
                except Exception as exc:  # the connection's teardown must still run
                    self._log.warning("close: leaving %r failed: %r", child, exc)
            try:
                self._held.exit(max(0.0, deadline - _now()))
            except TimeoutError as exc:
                self._log.warning("close: %s", exc)
            except NotConnected:
                pass  # the worker had stopped: nothing left to tear down
        finally:
            if not self._worker.stop(max(JOIN_S, deadline - _now())):
                self._log.warning(
                    "close: the worker thread %s did not end in time", self._worker.thread.name
                )

    @property
    def closed(self) -> bool:
        """True once :meth:`close` was called."""
        return self._closed

    # The properties below read the async client's namesakes from the
    # calling thread (each is one attribute read). @_mirrors carries their
    # docstrings from Client; the note here is what the API reference shows.
    @property
    @_mirrors
    def status(self) -> Status:
        """The client's status, :attr:`Client.status`: ``"closed"`` after :meth:`close`."""
        return self._client.status

    @property
    @_mirrors
    def last_error(self) -> BaseException | None:
        """Why the connection was lost, or None: :attr:`Client.last_error`."""
        return self._client.last_error

    @property
    @_mirrors
    def connected(self) -> bool:
        """True while the connection is up: :attr:`Client.connected`."""
        return self._client.connected

    @property
    @_mirrors
    def protocol(self) -> str:
        """The transport in use: :attr:`Client.protocol`."""
        return self._client.protocol

    @property
    @_mirrors
    def server_info(self) -> ServerInfo:
        """What the server said about itself: :attr:`Client.server_info`."""
        return self._client.server_info

    @property
    @_mirrors
    def playback_state(self) -> PlaybackState | None:
        """:attr:`Client.playback_state`."""
        return self._client.playback_state

    @property
    @_mirrors
    def server_time(self) -> int | None:
        """:attr:`Client.server_time`."""
        return self._client.server_time

    @property
    @_mirrors
    def topics(self) -> list[TopicInfo]:
        """:attr:`Client.topics`, as a list of its own (a snapshot)."""
        return list(self._client.topics)

    @property
    @_mirrors
    def services(self) -> list[ServiceInfo]:
        """:attr:`Client.services`, as a list of its own (a snapshot)."""
        return list(self._client.services)

    @property
    @_mirrors
    def rejections(self) -> dict[str, int]:
        """Inbound frames skipped or refused, per reason: :attr:`Client.rejections`."""
        return self._client.rejections

    @_mirrors
    def stats(self) -> ConnectionStats:
        """Bytes and messages read from the network: :meth:`Client.stats`
        (read in the calling thread: two integer reads)."""
        return self._client.stats()

    @property
    def worker_thread(self) -> threading.Thread:
        """The thread whose event loop runs the async client."""
        return self._worker.thread

    def _call(
        self, fn: Callable[..., Awaitable[T]], *args: Any, timeout: float | None, what: str
    ) -> T:
        if self._closed:
            raise NotConnected(f"{what}: the client is closed")
        return self._worker.run_bounded(fn, args, timeout, what)

    def run(self, fn: Callable[[Client], Awaitable[T]], *, timeout: float | None = None) -> T:
        """Run ``await fn(client)`` in the worker's event loop with the async
        :class:`~ros_mobile_bridge.Client`, and return its result: the way to
        reach what has no blocking method here (``watch_topics()``,
        ``subscribe(...).batches()``, several calls at once in a task group).
        ``fn`` must not keep the client for use outside the loop. Without
        ``timeout`` this waits as long as ``fn`` runs."""
        return self._call(fn, self._client, timeout=timeout, what="run")

    @_mirrors
    def wait_for_topic(self, topic: str, *, timeout: float | None = None) -> TopicInfo:
        """:meth:`Client.wait_for_topic`, blocking."""
        return self._call(
            _wait_for_topic, self._client, topic, timeout, timeout=None, what=f"wait for {topic}"
        )

    @_mirrors
    def wait_for_service(self, name: str, *, timeout: float | None = None) -> ServiceInfo:
        """:meth:`Client.wait_for_service`, blocking."""
        return self._call(
            _wait_for_service, self._client, name, timeout, timeout=None, what=f"wait for {name}"
        )

    # -- publishing ---------------------------------------------------------
    @overload
    def publish(
        self,
        topic: str,
        schema: RosMessage,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
        timeout: float | None = None,
    ) -> None: ...

    @overload
    def publish(
        self,
        topic: str,
        schema: str,
        data: Mapping[str, Any] | RosMessage,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
        timeout: float | None = None,
    ) -> None: ...

    @_mirrors
    def publish(
        self,
        topic: str,
        schema: str | RosMessage,
        data: Mapping[str, Any] | RosMessage | None = None,
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
        timeout: float | None = None,
    ) -> None:
        """:meth:`Client.publish`, blocking: a data frame returns once queued,
        a control frame once written to the socket (``NotConnected`` when it
        was not)."""
        self._call(
            _publish,
            self._client,
            topic,
            schema,
            data,
            priority,
            check_velocity,
            timeout=timeout,
            what=f"publish to {topic}",
        )

    @_mirrors
    def publish_zero_twist(
        self, topic: str = "/cmd_vel", schema: str | None = None, *, timeout: float | None = None
    ) -> None:
        """:meth:`Client.publish_zero_twist`, blocking."""
        self._call(
            self._client.publish_zero_twist,
            topic,
            schema,
            timeout=timeout,
            what=f"zero Twist to {topic}",
        )

    @_mirrors
    def advertise(
        self,
        topic: str,
        schema: str,
        *,
        latch: bool = False,
        queue_size: int | None = None,
        best_effort: bool = False,
        timeout: float | None = None,
    ) -> None:
        """:meth:`Client.advertise`, blocking."""
        options = (latch, queue_size, best_effort)
        self._call(
            _advertise, self._client, topic, schema, options, timeout=timeout, what="advertise"
        )

    @_mirrors
    def unadvertise(self, topic: str, *, timeout: float | None = None) -> None:
        """:meth:`Client.unadvertise`, blocking."""
        self._call(self._client.unadvertise, topic, timeout=timeout, what="unadvertise")

    # -- services and parameters -------------------------------------------
    @overload
    def call_service(
        self, name: str, request: RosRequest[_R], *, timeout: float | None = None
    ) -> _R: ...

    @overload
    def call_service(
        self,
        name: str,
        request: Mapping[str, Any] | RosMessage | None = None,
        *,
        timeout: float | None = None,
    ) -> Any: ...

    @_mirrors
    def call_service(
        self,
        name: str,
        request: Mapping[str, Any] | RosMessage | None = None,
        *,
        timeout: float | None = None,
    ) -> Any:
        """:meth:`Client.call_service`, blocking; ``timeout`` is the call's
        own (``ServiceTimeout``, default ``options.service_timeout``)."""
        return self._call(
            _call_service, self._client, name, request, timeout, timeout=None, what=name
        )

    @_mirrors
    def nodes(self) -> list[str]:
        """:meth:`Client.nodes`, blocking."""
        return self._call(_nodes, self._client, timeout=None, what="nodes")

    @_mirrors
    def topic_endpoints(self, topic: str) -> TopicEndpoints:
        """:meth:`Client.topic_endpoints`, blocking."""
        return self._call(self._client.topic_endpoints, topic, timeout=None, what="topic_endpoints")

    @_mirrors
    def control_playback(
        self, request: PlaybackRequest, *, timeout: float | None = None
    ) -> PlaybackState:
        """:meth:`Client.control_playback`, blocking; ``timeout`` is the request's own."""
        return self._call(
            _control_playback, self._client, request, timeout, timeout=None, what="playback"
        )

    @_mirrors
    def confirm_delivery(self, *, timeout: float | None = None) -> None:
        """:meth:`Client.confirm_delivery`, blocking; ``timeout`` is its own."""
        self._call(_confirm_delivery, self._client, timeout, timeout=None, what="confirmation")

    @_mirrors
    def fetch_asset(self, uri: str, *, timeout: float | None = None) -> bytes:
        """:meth:`Client.fetch_asset`, blocking; ``timeout`` is the request's own."""
        return self._call(_fetch_asset, self._client, uri, timeout, timeout=None, what=uri)

    @_mirrors
    def get_parameters(
        self, names: Sequence[str], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """:meth:`Client.get_parameters`, blocking."""
        return self._call(
            _get_parameters, self._client, names, timeout, timeout=None, what="get_parameters"
        )

    @_mirrors
    def set_parameters(
        self, values: Mapping[str, Any], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """:meth:`Client.set_parameters`, blocking."""
        return self._call(
            _set_parameters, self._client, values, timeout, timeout=None, what="set_parameters"
        )

    @_mirrors
    def list_parameters(self, *, timeout: float | None = None) -> dict[str, Any]:
        """:meth:`Client.list_parameters`, blocking."""
        return self._call(
            _list_parameters, self._client, timeout, timeout=None, what="list_parameters"
        )

    # -- schemas ------------------------------------------------------------
    @_mirrors
    def schema_template(self, name: str) -> dict[str, Any]:
        """:meth:`Client.schema_template`."""
        return self._call(
            _sync_call, self._client.schema_template, (name,), timeout=None, what="schema_template"
        )

    @_mirrors
    def schema_definition(self, name: str) -> list[FieldDef]:
        """:meth:`Client.schema_definition`."""
        return self._call(
            _sync_call,
            self._client.schema_definition,
            (name,),
            timeout=None,
            what="schema_definition",
        )

    @_mirrors
    def register_type(
        self, name: str, definition: str | bytes, *, encoding: str = "ros2msg"
    ) -> None:
        """:meth:`Client.register_type`."""

        def register() -> None:
            self._client.register_type(name, definition, encoding=encoding)

        self._call(_sync_call, register, (), timeout=None, what="register_type")

    @_mirrors
    def fetch_definition(self, name: str, *, timeout: float | None = None) -> bool:
        """:meth:`Client.fetch_definition`, blocking: asks the server for the
        definition of message type ``name`` where the protocol can; True
        when the type is known. ``timeout`` bounds the wait."""
        return self._call(
            _fetch_definition, self._client, name, timeout=timeout, what=f"fetch_definition({name})"
        )

    # -- subscriptions and actions -------------------------------------------
    @overload
    def subscribe(
        self,
        topic: str,
        type: type[_M],
        *,
        max_hz: float | None = None,
        adaptive: bool = True,
        dispatch: Dispatch = "all",
        schema: str | None = None,
        buffer: int | None = None,
        compression: Compression | None = None,
        decode: bool = True,
        save_bandwidth: SaveBandwidth = False,
        timeout: float | None = None,
    ) -> SyncSubscription[_M]: ...

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
        timeout: float | None = None,
    ) -> SyncSubscription[Any]: ...

    @_mirrors
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
        timeout: float | None = None,
    ) -> SyncSubscription[Any]:
        """:meth:`Client.subscribe`, as a (plain) context manager yielding a
        :class:`SyncSubscription`: ``for msg in sub`` or ``sub.get()``.
        ``timeout`` is the default wait for each message (None: until one
        comes or the subscription ends). Arguments are checked here, at
        once; the subscription starts when the block is entered.
        ``save_bandwidth`` as there: on Foxglove the stream pauses between
        deliveries, so a message published while paused (a stopping
        topic's last one) can be missed."""
        if self._closed:
            raise NotConnected("subscribe: the client is closed")
        _check_timeout(timeout)
        client = self._client

        def make() -> AbstractAsyncContextManager[Subscription[Any]]:
            # in the loop: a subscription's throttle belongs to the loop's lag monitor
            return client.subscribe(
                topic,
                type,
                max_hz=max_hz,
                adaptive=adaptive,
                dispatch=dispatch,
                schema=schema,
                buffer=buffer,
                compression=compression,
                decode=decode,
                save_bandwidth=save_bandwidth,
            )

        ctx = self._worker.run(_sync_call, make, (), what=f"subscribe to {topic}")
        held = Held(self._worker, ctx, f"the subscription to {topic}")
        return SyncSubscription(held, self._parent, topic, timeout)

    @overload
    def send_action_goal(
        self, action: str, action_type: RosGoal[_Res, _Fb]
    ) -> SyncActionGoal[_Res, _Fb]: ...

    @overload
    def send_action_goal(
        self, action: str, action_type: str, goal: Mapping[str, Any] | RosMessage
    ) -> SyncActionGoal[Any, Any]: ...

    @_mirrors
    def send_action_goal(
        self,
        action: str,
        action_type: str | RosGoal[Any, Any],
        goal: Mapping[str, Any] | RosMessage | None = None,
    ) -> SyncActionGoal[Any, Any]:
        """:meth:`Client.send_action_goal`, as a (plain) context manager
        yielding a :class:`SyncActionGoal`; the goal is sent when the block
        is entered, and leaving it before the goal ended cancels it."""
        if self._closed:
            raise NotConnected("send_action_goal: the client is closed")
        send: Any = self._client.send_action_goal  # the one implementation behind both forms
        cm = send(action, action_type, goal)
        return SyncActionGoal(Held(self._worker, cm, f"the goal to {action}"), self._parent, action)


# -- coroutines run in the worker's loop ---------------------------------------
async def _sync_call(fn: Callable[..., T], args: tuple[Any, ...]) -> T:
    return fn(*args)


async def _publish(
    client: Client,
    topic: str,
    schema: str | RosMessage,
    data: Mapping[str, Any] | RosMessage | None,
    priority: Priority,
    check_velocity: bool,
) -> None:
    publish: Any = client.publish  # the one implementation behind both forms
    await publish(topic, schema, data, priority=priority, check_velocity=check_velocity)


async def _advertise(
    client: Client, topic: str, schema: str, options: tuple[bool, int | None, bool]
) -> None:
    latch, queue_size, best_effort = options
    await client.advertise(
        topic, schema, latch=latch, queue_size=queue_size, best_effort=best_effort
    )


async def _wait_for_topic(client: Client, topic: str, timeout: float | None) -> TopicInfo:
    return await client.wait_for_topic(topic, timeout=timeout)


async def _wait_for_service(client: Client, name: str, timeout: float | None) -> ServiceInfo:
    return await client.wait_for_service(name, timeout=timeout)


async def _call_service(
    client: Client,
    name: str,
    request: Mapping[str, Any] | RosMessage | None,
    timeout: float | None,
) -> Any:
    return await client.call_service(name, request, timeout=timeout)


async def _nodes(client: Client) -> list[str]:
    return await client.nodes()


async def _control_playback(
    client: Client, request: PlaybackRequest, timeout: float | None
) -> PlaybackState:
    return await client.control_playback(request, timeout=timeout)


async def _confirm_delivery(client: Client, timeout: float | None) -> None:
    await client.confirm_delivery(timeout=timeout)


async def _fetch_asset(client: Client, uri: str, timeout: float | None) -> bytes:
    return await client.fetch_asset(uri, timeout=timeout)


async def _get_parameters(
    client: Client, names: Sequence[str], timeout: float | None
) -> dict[str, Any]:
    return await client.get_parameters(names, timeout=timeout)


async def _set_parameters(
    client: Client, values: Mapping[str, Any], timeout: float | None
) -> dict[str, Any]:
    return await client.set_parameters(values, timeout=timeout)


async def _list_parameters(client: Client, timeout: float | None) -> dict[str, Any]:
    return await client.list_parameters(timeout=timeout)


async def _fetch_definition(client: Client, name: str) -> bool:
    return await client.fetch_definition(name)


def _now() -> float:
    return time.monotonic()
