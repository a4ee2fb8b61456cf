"""The connection's life, under the public :class:`~ros_mobile_bridge.Client`:
its tasks (reader, writer, keep-alive, lag sampler, reliability), the
reconnect and the restore of what the lost connection carried, and the
teardown that sends the zero Twist. It owns the adapter in use, the
:class:`~._outbound.Outbound` and the :class:`~._router.Router`; nothing
here is a public API."""

from __future__ import annotations

import logging
import random
import time
from collections.abc import Awaitable, Callable, Mapping
from typing import Any, Final, Generic, Literal, TypeVar, overload

import anyio
import anyio.abc

from .._checks import check_timeout, nearest_hint
from .._errors import (
    ConnectError,
    DecodeError,
    NotConnected,
    NotSupportedError,
    ServiceError,
    ServiceTimeout,
    connection_lost,
)
from .._loop._wakeup import serve_timers
from .._options import ClientOptions
from .._types import ServiceInfo, Status, TopicInfo
from ..adapters import (
    Adapter,
    AssetFetcher,
    NodeLister,
    PlaybackControl,
    ServiceHost,
    require,
)
from ..adapters._seam import Part
from ..codec import same_type_name
from ..flow import Bucket, Subscription, ThrottleMode, Watchable, Watcher, participate
from ..interfaces._base import RosMessage
from ._outbound import Outbound
from ._router import Route, Router
from ._serve import ServedServices

__all__ = [
    "TWIST",
    "TWIST_STAMPED",
    "Connection",
    "RouteContext",
    "SubscriptionContext",
    "is_velocity_type",
    "zero_twist",
]

_M = TypeVar("_M", bound=RosMessage)
_Info = TypeVar("_Info", TopicInfo, ServiceInfo)
_T = TypeVar("_T")

TWIST: Final = "geometry_msgs/msg/Twist"
TWIST_STAMPED: Final = "geometry_msgs/msg/TwistStamped"


def is_velocity_type(schema: str) -> bool:
    """Twist or TwistStamped, however the name is spelled."""
    return same_type_name(schema, TWIST) or same_type_name(schema, TWIST_STAMPED)


def zero_twist(schema: str) -> dict[str, Any]:
    """The zero velocity of ``schema`` (a TwistStamped is stamped now)."""
    if same_type_name(schema, TWIST_STAMPED):
        now = time.time_ns()
        return {"header": {"stamp": {"sec": now // 1_000_000_000, "nanosec": now % 1_000_000_000}}}
    return {}


class Connection:
    """One client's connection to one robot, across reconnects. Built
    connected (``adapter``); :meth:`start` runs its tasks in the caller's
    task group, :meth:`teardown` ends it, :meth:`close_adapter` closes the
    socket."""

    def __init__(
        self,
        adapter: Adapter,
        options: ClientOptions,
        presets: Mapping[ThrottleMode, tuple[Bucket, ...]],
        reopen: Callable[[], Awaitable[Adapter]] | None = None,
    ) -> None:
        self.adapter = adapter
        """The adapter in use (the lost one until a reconnect restores)."""
        self._options = options
        self._log: logging.Logger = options.logger
        self._reopen = reopen
        self.status: Watchable[Status] = Watchable("connected")
        self.last_error: BaseException | None = None
        self.outbound = Outbound(adapter)
        self.router = Router(adapter, options, presets, self.status, self.outbound)
        self.served = ServedServices(options.teardown_timeout, options.logger)
        self.velocity: dict[str, str] = {}
        """Velocity topic -> the type this client published there."""
        # topic -> the publisher options advertise was given (latch, queue_size,
        # best_effort), for the restore after a reconnect
        self._publisher_options: dict[str, dict[str, Any]] = {}
        self._task_scopes: dict[str, anyio.CancelScope] = {}
        self._traffic_before = (0, 0)  # bytes and messages of the connections lost
        self._closing = False

    @property
    def connected(self) -> bool:
        return self.status.value == "connected"

    def require_connected(self) -> None:
        """Raise ``NotConnected`` unless the connection is up. While it is
        being re-established the message says so."""
        if self.status.value != "connected":
            raise NotConnected(
                f"the connection is {self.status.value}"
                + (f": {self.last_error}" if self.last_error else "")
            )

    async def request(
        self,
        what: str,
        call: Callable[[float], Awaitable[_T]],
        timeout: float | None,
        *,
        slack: float = 0.0,
    ) -> _T:
        """Run one correlated request under its deadline (``timeout`` or
        ``options.service_timeout``) and report its round trip to
        ``on_latency``. ``call`` gets the limit (an adapter may forward it);
        the local deadline is ``slack`` later, so the server's own timeout
        answer arrives first. ``ServiceTimeout`` names ``what``."""
        limit = check_timeout(timeout) or self._options.service_timeout
        self.require_connected()
        start = time.perf_counter()
        with anyio.move_on_after(limit + slack) as scope:
            result = await call(limit)
        if scope.cancelled_caught:
            raise ServiceTimeout(what, limit)
        self._options.report_latency((time.perf_counter() - start) * 1000.0)
        return result

    async def confirm_delivery(self, timeout: float | None) -> None:
        """:meth:`Client.confirm_delivery`: the outbox written, then the
        adapter's round trip, within one deadline; ``NotConnected`` when the
        connection it started on is gone or replaced by then."""
        adapter = self.adapter
        if not adapter.confirms_delivery:
            raise NotSupportedError(
                f"{adapter.protocol} cannot confirm delivery: a zenoh put has no acknowledgement,"
                " and no query proves the router has it"
            )

        async def confirm(limit: float) -> None:
            await self.outbound.drain(limit)
            await adapter.confirm_delivery()
            if self.adapter is not adapter or not self.connected:
                raise connection_lost("the connection went down before delivery was confirmed")

        await self.request("confirming delivery", confirm, timeout)

    @overload
    def offered(self, name: Literal["node_list"]) -> NodeLister: ...

    @overload
    def offered(self, name: Literal["assets"]) -> AssetFetcher: ...

    @overload
    def offered(self, name: Literal["playback"]) -> PlaybackControl: ...

    def offered(self, name: Part) -> Any:
        """The connected adapter's optional part ``name`` (``NotConnected``
        when there is none connected; the one ``NotSupportedError`` of
        :func:`~..adapters.require` when it lacks the part)."""
        self.require_connected()
        return require(getattr(self.adapter, name), name, self.adapter.protocol)

    async def advertise(self, topic: str, schema: str, options: dict[str, Any]) -> None:
        """Advertise ``topic`` with the publisher ``options`` (checked
        keyword arguments of the adapter's ``advertise``), which a reconnect
        restores with it; forgotten by :meth:`unadvertise`. ``NotConnected``
        unless connected."""
        self.require_connected()
        new = topic not in self.adapter.publishing()
        await self.adapter.advertise(topic, schema, **options)
        if new:
            self._publisher_options[topic] = options

    async def unadvertise(self, topic: str) -> None:
        """Stop publishing ``topic`` (``NotConnected`` unless connected)."""
        self.require_connected()
        self._publisher_options.pop(topic, None)
        await self.adapter.unadvertise(topic)

    def current(self) -> Adapter | None:
        """The adapter while connected, else None."""
        return self.adapter if self.connected else None

    def current_host(self) -> ServiceHost | None:
        """The adapter's serving part while connected, else None."""
        return self.adapter.serving if self.connected else None

    async def wait_listed(
        self,
        kind: str,
        name: str,
        watch: Callable[[], Watcher[list[_Info]]],
        timeout: float | None,
    ) -> _Info:
        """(``Client.wait_for_topic`` / ``wait_for_service``:) the entry of
        ``name`` once ``watch()``'s list has it. Watches the list and the
        status together, in the call's own task group (both end with the
        call): the first of the name listed, the connection ended, or the
        deadline."""
        limit = check_timeout(timeout)
        if self.status.value != "reconnecting":
            self.require_connected()
        found: list[_Info] = []
        known: list[str] = []
        ended: list[Status] = []

        async def look(scope: anyio.CancelScope) -> None:
            async for listed in watch():
                match = [info for info in listed if info.name == name]
                if match:
                    found.append(match[0])
                    scope.cancel()
                    return
                known[:] = [info.name for info in listed]

        async def status(scope: anyio.CancelScope) -> None:
            async for now in self.status.watch():
                if now in ("error", "closed"):
                    ended.append(now)
                    scope.cancel()
                    return

        with anyio.move_on_after(limit if limit is not None else float("inf")):
            async with anyio.create_task_group() as tg:
                tg.start_soon(look, tg.cancel_scope)
                tg.start_soon(status, tg.cancel_scope)
        if found:
            return found[0]
        if ended:
            reason = f": {self.last_error}" if self.last_error else ""
            how = "was lost for good" if ended[0] == "error" else "closed"
            raise NotConnected(f"the connection {how} before {kind} {name} appeared{reason}")
        assert limit is not None
        raise TimeoutError(
            f"the robot did not offer {kind} {name} within {limit:g} s{nearest_hint(name, known)}"
        )

    # -- tasks -----------------------------------------------------------------
    def start(self, tg: anyio.abc.TaskGroup) -> None:
        """Start the tasks in ``tg``. Each runs in its own shielded scope:
        cancelling the scope around the ``connect()`` block must not stop
        the reader before the teardown has confirmed the zero Twist.
        :meth:`stop_tasks` ends them."""
        for fn, name in (
            (self._supervise, "rmb-reader"),
            (self._writer, "rmb-writer"),
            (self._keepalive, "rmb-keepalive"),
            (participate, "rmb-lag"),
            (serve_timers, "rmb-timers"),
            (self.router.run_reliability, "rmb-reliability"),
        ):
            scope = anyio.CancelScope(shield=True)
            self._task_scopes[name] = scope
            tg.start_soon(self._owned, fn, scope, name=name)

    @staticmethod
    async def _owned(fn: Callable[[], Awaitable[None]], scope: anyio.CancelScope) -> None:
        with scope:
            await fn()

    def stop_tasks(self) -> None:
        for scope in self._task_scopes.values():
            scope.cancel()

    async def _supervise(self) -> None:
        """The reader task: run the adapter's reader (its events go to the
        router); when the connection is lost, re-establish it under
        ``options.reconnect`` and run again."""
        while True:
            try:
                await self.adapter.run(self.router)
                return
            except ConnectError as exc:
                error: ConnectError = exc
            except Exception as exc:  # a bug must not take the user's program down
                self._log.exception("the reader failed")
                error = ConnectError(f"internal error in the reader: {exc!r}")
            if self._closing:
                return
            self._disconnected(error)
            if not await self._reconnect(error):
                return

    def _disconnected(self, error: ConnectError) -> None:
        """The connection is gone: fail what waits on it (every call, goal
        and parameter operation in flight, at once, with ``NotConnected``
        "the connection was lost: ...", whatever the reconnect policy: the
        request was lost with the connection), keep what can be restored
        (subscriptions, advertisements, parameter watches)."""
        self._log.warning("connection lost: %s", error)
        self.last_error = error
        self.adapter.fail_pending(connection_lost(error))
        self.outbound.adapter = None
        dropped = self.outbound.outbox.clear()
        self.outbound.settle_all(error)
        if dropped:
            # a velocity command replayed seconds later could move the robot
            self._log.warning("dropped %d queued outgoing frames with the connection", dropped)
        self.router.connection_lost()
        if self._reopen is not None and self._options.reconnect is not None:
            self.status.set("reconnecting")
        else:
            self._give_up(error)

    def _give_up(self, error: ConnectError) -> None:
        self.last_error = error
        self.status.set("error")
        lost = connection_lost(error)
        self.router.fail_all(lost)
        self.served.fail_all(lost)

    async def _reconnect(self, error: ConnectError) -> bool:
        """Re-open the connection and restore its state. Returns False (with
        status ``"error"``) when the policy gives up."""
        policy = self._options.reconnect
        reopen = self._reopen
        if policy is None or reopen is None:
            return False
        attempt = 0
        old = self.adapter
        with anyio.CancelScope(shield=True):
            await old.aclose()
        while policy.max_attempts is None or attempt < policy.max_attempts:
            attempt += 1
            delay = policy.delay(attempt, random.random)
            self._log.info("reconnecting in %.2f s (attempt %d)", delay, attempt)
            await anyio.sleep(delay)
            try:
                adapter = await reopen()
            except ConnectError as exc:
                self._log.info("reconnect attempt %d failed: %s", attempt, exc)
                self.last_error = exc
                continue
            try:
                await self.restore(old, adapter)
            except ConnectError as exc:
                self._log.info("restoring after reconnect failed: %s", exc)
                self.last_error = exc
                with anyio.CancelScope(shield=True):
                    await adapter.aclose()
                continue
            except BaseException:
                with anyio.CancelScope(shield=True):
                    await adapter.aclose()
                raise
            self._log.info("reconnected after %d attempt(s)", attempt)
            self.outbound.adapter = adapter
            self.status.set("connected")
            return True
        self._log.error("giving up after %d reconnect attempts", attempt)
        self._give_up(self.last_error if isinstance(self.last_error, ConnectError) else error)
        return False

    def traffic(self) -> tuple[int, int]:
        """Bytes and messages received over the client's life, every
        connection it made included."""
        before_bytes, before_messages = self._traffic_before
        adapter = self.adapter
        return (
            before_bytes + adapter.bytes_received,
            before_messages + adapter.messages_received,
        )

    async def restore(self, old: Adapter, adapter: Adapter) -> None:
        """Bring a fresh connection to the state the lost one had."""
        if old is self.adapter:  # a failed restore was counted already
            self._traffic_before = self.traffic()
        self.adapter = adapter
        self.router.adapter = adapter
        for topic, schema in old.publishing().items():
            # unconfirmed: the new connection's reader starts after this
            options = self._publisher_options.get(topic, {})
            await adapter.advertise(topic, schema, confirm=False, **options)
        await self.router.restore()
        await self.served.restore(adapter.serving)

    async def next_connection(self, lost: Adapter | None) -> bool:
        """Wait until a connection other than ``lost`` is up (the reader
        handles the loss and the reconnect). False once the client is closed
        or has given up."""
        async for status in self.status.watch():
            if status in ("closed", "error"):
                return False
            if status == "connected" and self.adapter is not lost:
                return True
        return False

    async def _writer(self) -> None:
        await self.outbound.run_writer(self.next_connection)

    async def _keepalive(self) -> None:
        while True:
            adapter = self.adapter
            await adapter.keepalive()  # returns when that connection is gone
            if not await self.next_connection(adapter):
                return

    # -- the end -----------------------------------------------------------------
    async def teardown(self) -> None:
        """Flush, zero Twist, confirm, in one shielded scope with a deadline."""
        self._closing = True
        options = self._options
        with anyio.CancelScope(shield=True):
            with anyio.move_on_after(options.teardown_timeout) as scope:
                if self.connected:
                    await self._flush_and_stop()
                elif options.zero_twist_on_exit and (targets := self.stop_targets()):
                    self._log.error(
                        "teardown: the connection is gone, so no zero Twist could be sent to %s;"
                        " only the robot's own cmd_vel watchdog can stop it now",
                        ", ".join(sorted(targets)),
                    )
            if scope.cancelled_caught:
                self._log.warning(
                    "teardown did not finish within %.3g s; closing anyway",
                    options.teardown_timeout,
                )
            if self.connected:
                self.status.set("closed")
            self.adapter.fail_pending(NotConnected("the client is closed"))
            # a control publish still waiting (its frame not written before
            # the teardown's deadline) must raise, never wait forever
            self.outbound.settle_all(ConnectError("the client closed before the frame was written"))
            self.router.close()
            self.served.fail_all(NotConnected("the client is closed"))
            self.status.close()

    async def _flush_and_stop(self) -> None:
        adapter = self.adapter
        outbound = self.outbound
        # The writer sends what is queued: cancelling it while it holds a
        # frame would lose that frame.
        await outbound.drain(self._options.teardown_timeout / 2)
        self._task_scopes["rmb-writer"].cancel()  # from here on the teardown writes
        try:
            await outbound.send_control()
            dropped = outbound.outbox.drop_data()
            if dropped:
                self._log.warning("teardown: %d queued data frames were not sent", dropped)
            if self._options.zero_twist_on_exit:
                for topic, schema in self.stop_targets().items():
                    try:
                        await adapter.advertise(topic, schema)
                        await adapter.send(adapter.encode_publish(topic, zero_twist(schema)))
                        self._log.info(
                            "teardown: zero %s sent to %s", schema.rsplit("/", 1)[-1], topic
                        )
                    except (NotSupportedError, DecodeError, ValueError) as exc:
                        self._log.error(
                            "teardown: could not send a zero Twist to %s: %s", topic, exc
                        )
            await adapter.confirm_delivery()
        except (ConnectError, NotConnected, ServiceError) as exc:
            self._log.error(
                "teardown: connection failed before the zero Twist was confirmed: %s", exc
            )

    def stop_targets(self) -> dict[str, str]:
        """Velocity topic -> schema, for every topic the zero Twist goes to."""
        targets = dict(self.velocity)
        for topic in self._options.stop_topics:
            if topic not in targets:
                targets[topic] = self.velocity_schema(topic)
        return targets

    def velocity_schema(self, topic: str) -> str:
        """What this client published on ``topic``, else TwistStamped when the
        server advertises it so, else Twist."""
        published = self.velocity.get(topic)
        if published is not None:
            return published
        for t in self.adapter.topics:
            if t.name == topic and same_type_name(t.schema_name, TWIST_STAMPED):
                return TWIST_STAMPED
        return TWIST

    async def close_adapter(self) -> None:
        with anyio.CancelScope(shield=True):
            await self.adapter.aclose()


class RouteContext:
    """Enter to route a subscription (``NotConnected`` unless the connection
    is up or being re-established: then it waits pending for the restore),
    exit to stop it. Yields the :class:`~._router.Route`."""

    def __init__(self, conn: Connection, route: Route) -> None:
        self._conn = conn
        self._route = route

    async def __aenter__(self) -> Route:
        conn = self._conn
        if conn.status.value != "reconnecting":
            conn.require_connected()
        await conn.router.add(self._route)
        return self._route

    async def __aexit__(self, *exc_info: object) -> None:
        await self._conn.router.remove(self._route)


class SubscriptionContext(Generic[_M]):
    """What :meth:`Client.subscribe` returns: enter to subscribe, exit to
    unsubscribe (the bridge stops sending once no local subscriber is left)."""

    def __init__(self, conn: Connection, route: Route) -> None:
        self._routed = RouteContext(conn, route)

    async def __aenter__(self) -> Subscription[_M]:
        return (await self._routed.__aenter__()).sub

    async def __aexit__(self, *exc_info: object) -> None:
        await self._routed.__aexit__(*exc_info)

    def __aiter__(self) -> None:
        raise TypeError(_SUBSCRIBE_HINT)

    def __iter__(self) -> None:
        raise TypeError(_SUBSCRIBE_HINT)


_SUBSCRIBE_HINT = (
    "subscribe() returns a context manager, not an iterator: "
    "use `async with client.subscribe(...) as sub: async for m in sub`"
)
