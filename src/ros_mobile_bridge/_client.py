"""The :class:`Client`: one API over every transport.

The client owns one task group (started by ``connect()``): the reader task
(socket -> wire engine -> router -> subscription queues), the writer task
(outbox -> socket) and the keep-alive task. It holds no wire format: every
protocol detail lives in the backend."""

from __future__ import annotations

import contextlib
import logging
import math
import random
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping, Sequence
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from functools import partial
from typing import TYPE_CHECKING, Any, Final, TypeVar

import anyio
import anyio.abc
import anyio.lowlevel

from ._action import ActionGoal
from ._errors import (
    ConnectError,
    DecodeError,
    NotConnected,
    NotSupportedError,
    RosBridgeError,
    SchemaError,
    ServiceTimeout,
)
from ._limits import truncate_for_log
from ._options import ClientOptions
from ._serve import DEFAULT_SERVE_BUFFER, DEFAULT_SERVE_TIMEOUT, ServiceRequests
from ._types import (
    Compression,
    Dispatch,
    Priority,
    ServerInfo,
    ServiceInfo,
    Status,
    TopicInfo,
)
from .backends import Backend, SubscribeHints
from .codec import CodecRegistry, FieldDef, same_type_name
from .flow import (
    AdaptiveThrottle,
    Bucket,
    FrameQueue,
    LagMonitor,
    Outbox,
    RawFrame,
    Subscription,
    ThrottleMode,
    Watchable,
    Watcher,
    WireMessage,
    current_monitor,
    participate,
    resolve_presets,
)

if TYPE_CHECKING:
    import os

    from ._record import Recording

__all__ = ["Client"]

_TWIST: Final = "geometry_msgs/msg/Twist"
_READER_YIELD_EVERY: Final = 64
T = TypeVar("T")
_TWIST_STAMPED: Final = "geometry_msgs/msg/TwistStamped"


def _is_velocity_type(schema: str) -> bool:
    return same_type_name(schema, _TWIST) or same_type_name(schema, _TWIST_STAMPED)


def _check_name(kind: str, name: object) -> str:
    if not isinstance(name, str):
        raise TypeError(f"{kind} must be a str, not {type(name).__name__}")
    if not name.startswith("/") or any(c.isspace() for c in name) or len(name) < 2:
        raise ValueError(f"{kind} must be an absolute ROS name like '/cmd_vel', got {name!r}")
    return name


def _check_schema(schema: object) -> str:
    if not isinstance(schema, str):
        raise TypeError(f"schema must be a str, not {type(schema).__name__}")
    if schema.count("/") not in (1, 2) or any(c.isspace() for c in schema):
        raise ValueError(
            f"schema must be a ROS type like 'geometry_msgs/msg/Twist', got {schema!r}"
        )
    return schema


def _check_timeout(timeout: object) -> float | None:
    if timeout is None:
        return None
    if isinstance(timeout, bool) or not isinstance(timeout, int | float):
        raise TypeError("timeout must be a number of seconds or None")
    if not timeout > 0 or math.isinf(timeout):
        raise ValueError(f"timeout must be a positive, finite number of seconds, got {timeout!r}")
    return float(timeout)


class _Receipt:
    """The fate of one control publish: settled once its frame, or the newer
    value for the same topic that replaced it in the outbox, is written to
    the socket (``error`` None), or once it cannot be (``error`` says why)."""

    __slots__ = ("covers", "done", "error")

    def __init__(self) -> None:
        self.done = anyio.Event()
        self.error: ConnectError | None = None
        self.covers: list[_Receipt] = []
        """Older receipts for the same topic whose frames this one replaced."""

    def absorb(self, older: _Receipt) -> None:
        """This receipt's frame replaced ``older``'s: settle them together."""
        self.covers.append(older)
        self.covers.extend(older.covers)
        older.covers = []

    def settle(self, error: ConnectError | None) -> None:
        for receipt in (self, *self.covers):
            receipt.error = error
            receipt.done.set()
        self.covers = []


class Client:
    """A connection to one robot. Obtain it from :func:`ros_mobile_bridge.connect`.

    Every method that talks to the robot raises ``NotConnected`` when the
    connection is closed or lost, and validates its arguments before doing
    anything (``ValueError`` / ``TypeError``)."""

    def __init__(
        self,
        backend: Backend,
        options: ClientOptions,
        reopen: Callable[[], Awaitable[Backend]] | None = None,
        presets: Mapping[ThrottleMode, tuple[Bucket, ...]] | None = None,
    ) -> None:
        self._backend = backend
        self._presets = (
            presets
            if presets is not None
            else resolve_presets(options.preset_overrides, options.logger)
        )
        mode = options.throttle_mode
        self._mode: Callable[[], ThrottleMode] = mode if callable(mode) else (lambda: mode)
        self._reopen = reopen
        self._watched_parameters: dict[str, int] = {}
        self._options = options
        self._log: logging.Logger = options.logger
        self._status: Watchable[Status] = Watchable("connected")
        self._topics: Watchable[list[TopicInfo]] = Watchable(backend.topics)
        self._services: Watchable[list[ServiceInfo]] = Watchable(backend.services)
        self._parameters: Watchable[dict[str, Any]] = Watchable({})
        self._last_error: BaseException | None = None
        self._subs: dict[str, list[Subscription]] = {}
        self._hints: dict[Subscription, SubscribeHints] = {}
        self._outbox = Outbox()
        self._receipts: dict[str, tuple[WireMessage, _Receipt]] = {}  # control frames queued
        self._velocity: dict[str, str] = {}
        self._task_scopes: dict[str, anyio.CancelScope] = {}
        self._closing = False
        self._writing = False
        self._wrote = anyio.Event()  # set after each frame the writer sends
        self._inbound = 0
        self._breaker_changed = anyio.Event()  # set by the tick when a breaker changed
        self._breaker_topics: set[str] = set()  # topics to subscribe again at the bridge
        self._forwarded_hz: dict[str, float | None] = {}  # the rate each topic's bridge sub asks
        self._user_types: dict[str, tuple[str, str | bytes]] = {}
        self._user_types_in: Backend | None = None  # the backend that holds them
        self._publish_checked: set[tuple[str, str, bool]] = set()
        self._publish_checked_for: tuple[Backend, list[TopicInfo]] | None = None
        self._rejections: dict[str, int] = {}
        self._served: dict[str, ServiceRequests] = {}

    # -- lifecycle ----------------------------------------------------------
    @property
    def status(self) -> Status:
        """``"connected"``; ``"reconnecting"`` while a lost connection is
        being re-established (``options.reconnect``); ``"closed"`` after the
        block ends; ``"error"`` once the connection is lost for good (see
        :attr:`last_error`)."""
        return self._status.value

    @property
    def last_error(self) -> BaseException | None:
        """Why the connection was lost, or None."""
        return self._last_error

    def watch_status(self) -> Watcher[Status]:
        """Async iterator: the current status at once, then every change."""
        return self._status.watch()

    @property
    def protocol(self) -> str:
        """The transport in use: ``"foxglove-ws"``, ``"rosbridge"`` or ``"zenoh"``."""
        return self._backend.protocol

    @property
    def server_info(self) -> ServerInfo:
        """What the server said about itself."""
        return self._backend.server_info

    @property
    def connected(self) -> bool:
        """True while the connection is up (``status == "connected"``)."""
        return self._status.value == "connected"

    def _require_connected(self) -> None:
        """Raise ``NotConnected`` unless the connection is up. While it is
        being re-established the message says so."""
        if self._status.value != "connected":
            raise NotConnected(
                f"the connection is {self._status.value}"
                + (f": {self._last_error}" if self._last_error else "")
            )

    def _start(self, tg: anyio.abc.TaskGroup) -> None:
        """Start the client's tasks in ``tg``. Each runs in its own shielded
        scope: cancelling the scope around the ``connect()`` block must not
        stop the reader before the teardown has confirmed the zero Twist.
        :meth:`_stop_tasks` ends them."""
        for fn, name in (
            (self._supervise, "rmb-reader"),
            (self._writer, "rmb-writer"),
            (self._keepalive, "rmb-keepalive"),
            (participate, "rmb-lag"),
            (self._reliability, "rmb-reliability"),
        ):
            scope = anyio.CancelScope(shield=True)
            self._task_scopes[name] = scope
            tg.start_soon(self._owned, fn, scope, name=name)

    @staticmethod
    async def _owned(fn: Any, scope: anyio.CancelScope) -> None:
        with scope:
            await fn()

    def _stop_tasks(self) -> None:
        for scope in self._task_scopes.values():
            scope.cancel()

    async def _supervise(self) -> None:
        """The reader task: run the backend's reader; when the connection is
        lost, re-establish it under ``options.reconnect`` and run again."""
        while True:
            try:
                await self._backend.run(self)
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
        """The connection is gone: fail what waits on it, keep what can be
        restored (subscriptions, advertisements, parameter watches)."""
        self._log.warning("connection lost: %s", error)
        self._last_error = error
        self._backend.fail_pending(NotConnected(f"disconnected: {error}"))
        dropped = self._outbox.clear()
        receipts, self._receipts = self._receipts, {}
        for _message, receipt in receipts.values():
            receipt.settle(error)
        if dropped:
            # a velocity command replayed seconds later could move the robot
            self._log.warning("dropped %d queued outgoing frames with the connection", dropped)
        for topic, subs in self._subs.items():
            self.on_topic_state(topic, False)
            for sub in subs:  # breaker timers die with the connection
                sub.breaker.reset()
                sub._queue.blocked = False
        if self._reopen is not None and self._options.reconnect is not None:
            self._status.set("reconnecting")
        else:
            self._give_up(error)

    def _give_up(self, error: ConnectError) -> None:
        self._last_error = error
        self._status.set("error")
        for subs in self._subs.values():
            for sub in subs:
                sub._fail(NotConnected(f"disconnected: {error}"))
        for served in self._served.values():
            served._fail(NotConnected(f"disconnected: {error}"))

    async def _reconnect(self, error: ConnectError) -> bool:
        """Re-open the connection and restore its state. Returns False (with
        status ``"error"``) when the policy gives up."""
        policy = self._options.reconnect
        reopen = self._reopen
        if policy is None or reopen is None:
            return False
        attempt = 0
        old = self._backend
        with anyio.CancelScope(shield=True):
            await old.aclose()
        while policy.max_attempts is None or attempt < policy.max_attempts:
            attempt += 1
            delay = policy.delay(attempt, random.random)
            self._log.info("reconnecting in %.2f s (attempt %d)", delay, attempt)
            await anyio.sleep(delay)
            try:
                backend = await reopen()
            except ConnectError as exc:
                self._log.info("reconnect attempt %d failed: %s", attempt, exc)
                self._last_error = exc
                continue
            try:
                await self._restore(old, backend)
            except ConnectError as exc:
                self._log.info("restoring after reconnect failed: %s", exc)
                self._last_error = exc
                with anyio.CancelScope(shield=True):
                    await backend.aclose()
                continue
            except BaseException:
                with anyio.CancelScope(shield=True):
                    await backend.aclose()
                raise
            self._log.info("reconnected after %d attempt(s)", attempt)
            self._status.set("connected")
            return True
        self._log.error("giving up after %d reconnect attempts", attempt)
        self._give_up(self._last_error if isinstance(self._last_error, ConnectError) else error)
        return False

    async def _restore(self, old: Backend, backend: Backend) -> None:
        """Bring a fresh connection to the state the lost one had."""
        self._backend = backend
        self.on_graph()
        for topic, schema in old.publishing().items():
            # unconfirmed: the new connection's reader starts after this
            await backend.advertise(topic, schema, confirm=False)
        for topic in list(self._subs):
            await self._sync_topic(topic)
        if self._watched_parameters:
            await backend.subscribe_parameters(sorted(self._watched_parameters))
        for name, served in list(self._served.items()):
            if self._served.get(name) is not served:
                continue  # its serve() block ended while this loop awaited
            # unconfirmed: a refusal arrives later, through the new reader,
            # and ends that serve() block (served.on_service_failed)
            await backend.advertise_service(name, served.service_type, served, confirm=False)

    async def _next_connection(self, lost: Backend) -> bool:
        """Wait until a connection other than ``lost`` is up (the reader
        handles the loss and the reconnect). False once the client is closed
        or has given up."""
        async for status in self._status.watch():
            if status in ("closed", "error"):
                return False
            if status == "connected" and self._backend is not lost:
                return True
        return False

    async def _writer(self) -> None:
        outbox = self._outbox
        while True:
            message = await outbox.get()
            backend = self._backend
            self._writing = True  # a frame taken from the outbox is not lost
            try:
                await self._write_taken(backend, message)
            except ConnectError:
                if not await self._next_connection(backend):
                    return
            finally:
                self._writing = False
                self._wrote.set()

    async def _drain_writer(self, budget: float) -> None:
        """Let the writer send what is queued (control first, then data) and
        finish the frame it holds, for at most ``budget`` seconds."""
        with anyio.move_on_after(budget):
            while len(self._outbox) or self._writing:
                self._wrote = anyio.Event()
                await self._wrote.wait()

    async def _keepalive(self) -> None:
        while True:
            backend = self._backend
            await backend.keepalive()  # returns when that connection is gone
            if not await self._next_connection(backend):
                return

    async def _teardown(self) -> None:
        """Flush, zero Twist, confirm, in one shielded scope with a deadline."""
        self._closing = True
        options = self._options
        with anyio.CancelScope(shield=True):
            with anyio.move_on_after(options.teardown_timeout) as scope:
                if self._status.value == "connected":
                    await self._flush_and_stop()
                elif options.zero_twist_on_exit and (targets := self._stop_targets()):
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
            if self._status.value == "connected":
                self._status.set("closed")
            self._backend.fail_pending(NotConnected("the client is closed"))
            # a control publish still waiting (its frame not written before
            # the teardown's deadline) must raise, never wait forever
            receipts, self._receipts = self._receipts, {}
            for _message, receipt in receipts.values():
                receipt.settle(ConnectError("the client closed before the frame was written"))
            for subs in self._subs.values():
                for sub in subs:
                    sub.close()
            for served in self._served.values():
                served._fail(NotConnected("the client is closed"))
            self._topics.close()
            self._services.close()
            self._parameters.close()
            self._status.close()

    async def _flush_and_stop(self) -> None:
        backend = self._backend
        outbox = self._outbox
        # The writer sends what is queued: cancelling it while it holds a
        # frame would lose that frame.
        await self._drain_writer(self._options.teardown_timeout / 2)
        self._task_scopes["rmb-writer"].cancel()  # from here on the teardown writes
        try:
            await self._send_control()
            dropped = outbox.drop_data()
            if dropped:
                self._log.warning("teardown: %d queued data frames were not sent", dropped)
            if self._options.zero_twist_on_exit:
                for topic, schema in self._stop_targets().items():
                    try:
                        await backend.advertise(topic, schema)
                        await backend.send(backend.encode_publish(topic, self._zero(schema)))
                        self._log.info(
                            "teardown: zero %s sent to %s", schema.rsplit("/", 1)[-1], topic
                        )
                    except (NotSupportedError, DecodeError, ValueError) as exc:
                        self._log.error(
                            "teardown: could not send a zero Twist to %s: %s", topic, exc
                        )
            await backend.confirm_delivery()
        except ConnectError as exc:
            self._log.error(
                "teardown: connection failed before the zero Twist was confirmed: %s", exc
            )

    def _stop_targets(self) -> dict[str, str]:
        """Velocity topic -> schema, for every topic the zero Twist goes to."""
        targets = dict(self._velocity)
        for topic in self._options.stop_topics:
            if topic not in targets:
                targets[topic] = self._velocity_schema(topic)
        return targets

    def _velocity_schema(self, topic: str) -> str:
        """What this client published on ``topic``, else TwistStamped when the
        server advertises it so, else Twist."""
        published = self._velocity.get(topic)
        if published is not None:
            return published
        for t in self._backend.topics:
            if t.name == topic and same_type_name(t.schema_name, _TWIST_STAMPED):
                return _TWIST_STAMPED
        return _TWIST

    @staticmethod
    def _zero(schema: str) -> dict[str, Any]:
        if same_type_name(schema, _TWIST_STAMPED):
            now = time.time_ns()
            return {
                "header": {"stamp": {"sec": now // 1_000_000_000, "nanosec": now % 1_000_000_000}}
            }
        return {}

    async def _close_backend(self) -> None:
        with anyio.CancelScope(shield=True):
            await self._backend.aclose()

    # -- events from the backend (reader task) -------------------------------
    def on_frame(self, frame: RawFrame) -> None:
        """Backend callback: route one frame to this topic's subscriptions."""
        subs = self._subs.get(frame.topic)
        if subs:
            for sub in subs:
                sub._queue.offer(frame)

    def on_graph(self) -> None:
        """Backend callback: the topic or service list changed."""
        self._topics.set(self._backend.topics)
        self._services.set(self._backend.services)

    def on_topic_state(self, topic: str, active: bool) -> None:
        """Backend callback: the server now carries ``topic`` to us, or not."""
        for sub in self._subs.get(topic, ()):
            sub._set_state("active" if active else "pending")

    def on_rejected(self, reason: str, detail: str, count: int = 1) -> None:
        """Backend callback: ``count`` inbound frames were skipped or refused
        for one reason. Counted per ``reason`` (see :attr:`rejections`) and
        logged once per call, truncated."""
        self._rejections[reason] = self._rejections.get(reason, 0) + count
        if count == 1:
            self._log.warning(
                "skipped input from the server (%s): %s", reason, truncate_for_log(detail)
            )
        else:
            self._log.warning(
                "skipped %d inputs from the server (%s): %s",
                count,
                reason,
                truncate_for_log(detail),
            )

    @property
    def rejections(self) -> dict[str, int]:
        """How many inbound frames were skipped or refused, per reason (a
        snapshot, counted over the client's life, across reconnects). Keys:
        ``"invalid_utf8"``, ``"malformed"``, ``"json_depth"``,
        ``"schema_too_large"``, ``"channel_limit"``, ``"service_limit"``,
        ``"fragment_limit"``; see the limits in :class:`ClientOptions`."""
        return dict(self._rejections)

    def on_parameters(self, values: Mapping[str, Any]) -> None:
        """Backend callback: unsolicited parameter values arrived."""
        merged = dict(self._parameters.value)
        merged.update(values)
        self._parameters.set(merged)

    async def _send_control(self) -> None:
        """Write every queued control frame now (the writer task would only
        get to them on its next turn). Raises ``ConnectError`` when a write
        fails: the connection is lost (the reader handles that)."""
        outbox = self._outbox
        backend = self._backend
        while (message := outbox.pop_control()) is not None:
            await self._write_taken(backend, message)

    def _queue_control(self, topic: str, message: WireMessage) -> _Receipt:
        """Put a control frame in the outbox; its receipt settles when it (or
        a newer value for ``topic``) is written, or cannot be."""
        receipt = _Receipt()
        queued = self._receipts.get(topic)
        if queued is not None:  # still unsent: the outbox replaces it
            receipt.absorb(queued[1])
        self._outbox.put_control(topic, message)
        self._receipts[topic] = (message, receipt)
        return receipt

    async def _write_taken(self, backend: Backend, message: WireMessage) -> None:
        """Write ``message``, just taken from the outbox, and settle its
        receipt if it is a control frame. Cancelled before the write began
        (a write, once begun, is finished), a control frame goes back to the
        outbox unless a newer value for its topic is queued already."""
        taken: tuple[str, _Receipt] | None = None
        if self._receipts:
            for topic, (queued, receipt) in self._receipts.items():
                if queued is message:
                    del self._receipts[topic]
                    taken = topic, receipt
                    break
        try:
            await backend.send(message)
        except ConnectError as exc:
            if taken is not None:
                taken[1].settle(exc)
            raise
        except BaseException:
            if taken is not None:
                topic, receipt = taken
                newer = self._receipts.get(topic)
                if newer is not None:
                    newer[1].absorb(receipt)
                elif backend is self._backend and self._status.value == "connected":
                    self._outbox.put_control(topic, message)
                    self._receipts[topic] = (message, receipt)
                else:
                    receipt.settle(ConnectError("the connection closed before it was written"))
            raise
        if taken is not None:
            taken[1].settle(None)

    async def before_inbound(self) -> None:
        """Backend callback, before each inbound message: send pending control
        frames first, and every 64 messages let the consumers run, so a burst
        read in one go does not overflow their queues before they wake."""
        if self._outbox.has_control:
            with contextlib.suppress(ConnectError):  # the reader's next read reports it
                await self._send_control()
        self._inbound += 1
        if self._inbound >= _READER_YIELD_EVERY:
            self._inbound = 0
            await anyio.lowlevel.checkpoint()

    # -- discovery ----------------------------------------------------------
    @property
    def topics(self) -> list[TopicInfo]:
        """The topics the server offers now."""
        return self._topics.value

    @property
    def services(self) -> list[ServiceInfo]:
        """The services the server offers now."""
        return self._services.value

    def watch_topics(self) -> Watcher[list[TopicInfo]]:
        """Async iterator: the topic list at once, then every change."""
        return self._topics.watch()

    def watch_services(self) -> Watcher[list[ServiceInfo]]:
        """Async iterator: the service list at once, then every change."""
        return self._services.watch()

    # -- subscriptions ------------------------------------------------------
    def subscribe(
        self,
        topic: str,
        *,
        max_hz: float | None = None,
        adaptive: bool = True,
        dispatch: Dispatch = "all",
        schema: str | None = None,
        buffer: int | None = None,
        compression: Compression | None = None,
    ) -> _SubscriptionContext:
        """Subscribe to ``topic``; an async context manager yielding a
        :class:`~ros_mobile_bridge.Subscription` (``async for msg in sub``).

        The topic need not be advertised yet: the subscription stays
        ``pending`` and becomes ``active`` when the server offers it.
        ``max_hz`` caps the delivery rate (frames in between are dropped
        before decoding; the newest one is delivered at the end of the
        window). ``adaptive`` lets the event loop's lag widen that interval
        (``options.throttle_mode``); the effective interval is the larger of
        the two, and a subscription with ``adaptive=False`` ignores the lag
        (and its breaker never trips on its own). ``dispatch="latest"`` keeps only the newest undelivered
        message; ``"all"`` queues up to ``buffer`` and drops the oldest when
        the consumer falls behind. ``compression`` (rosbridge only, ignored
        elsewhere): ``"cbor"`` or ``"cbor-raw"`` (CDR, decoded here) instead
        of JSON; images are far smaller and cheaper to decode. Arguments are
        checked here, at once."""
        _check_name("topic", topic)
        if schema is not None:
            _check_schema(schema)
        if compression is not None and compression not in ("cbor", "cbor-raw"):
            raise ValueError(f"compression must be 'cbor', 'cbor-raw' or None, got {compression!r}")
        if not isinstance(adaptive, bool):
            raise TypeError("adaptive must be a bool")
        throttle = (
            AdaptiveThrottle(
                self._presets, self._mode, current_monitor(), logger=self._log, name=topic
            )
            if adaptive
            else None
        )
        queue = FrameQueue(
            max_hz=max_hz,
            dispatch=dispatch,
            buffer=self._options.subscription_buffer if buffer is None else buffer,
            adaptive=throttle.interval_s if throttle is not None else None,
        )
        policy = self._options.breaker
        breaker = policy.build() if policy is not None else None
        sub = Subscription(topic, queue, logger=self._log, throttle=throttle, breaker=breaker)
        return _SubscriptionContext(
            self, sub, SubscribeHints(max_hz=max_hz, schema=schema, compression=compression)
        )

    def _rate_for(self, sub: Subscription) -> float | None:
        """The rate the bridge need not exceed for ``sub`` (None: all): its
        ``max_hz``, tightened by its adaptive throttle's current interval.
        rosbridge gets it as ``throttle_rate``; the other bridges have no
        such option."""
        hz = self._hints[sub].max_hz
        throttle = sub._throttle
        if throttle is not None and (interval := throttle.interval) > 0.0:
            adaptive = 1.0 / interval
            hz = adaptive if hz is None else min(hz, adaptive)
        return hz

    def _merged_hints(self, topic: str) -> SubscribeHints:
        subs = [s for s in self._subs.get(topic, ()) if not s._queue.blocked]
        hints = [self._hints[s] for s in subs]
        caps = [self._rate_for(s) for s in subs]
        loosest = None if not caps or None in caps else max(c for c in caps if c is not None)
        schema = next((h.schema for h in hints if h.schema), None)
        compression = next((h.compression for h in hints if h.compression), None)
        return SubscribeHints(max_hz=loosest, schema=schema, compression=compression)

    async def _subscribe_at_bridge(self, topic: str, backend: Backend | None = None) -> None:
        """Subscribe (again) at the bridge with the merged hints of the local
        subscriptions, and remember the rate forwarded."""
        hints = self._merged_hints(topic)
        self._forwarded_hz[topic] = hints.max_hz
        await (backend or self._backend).subscribe(topic, hints)

    async def _add_subscription(self, sub: Subscription, hints: SubscribeHints) -> None:
        reconnecting = self._status.value == "reconnecting"
        if not reconnecting:
            self._require_connected()
        self._subs.setdefault(sub.topic, []).append(sub)
        self._hints[sub] = hints
        if reconnecting:
            return  # pending; the reconnect subscribes it
        try:
            await self._subscribe_at_bridge(sub.topic)
        except BaseException:
            await self._remove_subscription(sub)
            raise
        if self._backend.topic_active(sub.topic):
            sub._set_state("active")

    async def _sync_topic(self, topic: str) -> None:
        """Make the bridge carry ``topic`` exactly when a local subscription
        whose breaker is not tripped wants it."""
        backend = self._backend
        if any(not s._queue.blocked for s in self._subs.get(topic, ())):
            await self._subscribe_at_bridge(topic, backend)
            if backend.topic_active(topic):
                self.on_topic_state(topic, True)
        else:
            self._forwarded_hz.pop(topic, None)
            await backend.unsubscribe(topic)
            self.on_topic_state(topic, False)

    async def _reliability(self) -> None:
        """Apply breaker and forwarded-rate changes at the bridge. The checks
        run in :meth:`_reliability_tick`,
        which the event loop's shared lag sampler calls every 200 ms for every
        client on the loop (one wake-up per loop, not one per client); this
        task wakes only when a breaker changed state and the bridge must stop
        or resume sending a topic."""
        monitor = current_monitor()
        key = monitor.add_tick(partial(self._reliability_tick, monitor))
        try:
            while True:
                await self._breaker_changed.wait()
                self._breaker_changed = anyio.Event()
                topics, self._breaker_topics = self._breaker_topics, set()
                for topic in sorted(topics):
                    if topic not in self._subs or self._status.value != "connected":
                        continue
                    try:
                        await self._sync_topic(topic)
                    except ConnectError as exc:
                        self._log.debug("bridge change on %s not applied: %s", topic, exc)
                    except Exception:  # a bug must not take the user's program down
                        self._log.exception("bridge change on %s failed", topic)
        finally:
            monitor.remove_tick(key)

    def _reliability_tick(self, monitor: LagMonitor) -> None:
        """Every 200 ms (see :meth:`_reliability`): refresh each adaptive
        subscription's throttle, feed its breaker the lag, and note for
        :meth:`_reliability` to apply at the bridge the topics whose breakers
        changed (tripped: the bridge stops sending; half-open or closed: it
        sends again) or whose forwarded rate moved with an adaptive throttle
        (rosbridge's ``throttle_rate``)."""
        if not self._subs or self._status.value != "connected":
            return
        lag = monitor.recurring_lag_ms()  # the loop's monitor, not looked up per client
        policy = self._options.breaker
        for topic, subs in self._subs.items():
            for sub in subs:
                throttle = sub._throttle
                if throttle is not None and policy is not None:
                    throttle.interval_s()  # refresh at_deepest
                    sub.breaker.observe(lag, throttle.at_deepest)
                else:
                    sub.breaker.poll()
                blocked = sub.breaker.state in ("tripped_auto", "tripped_manual")
                if blocked != sub._queue.blocked:
                    sub._queue.blocked = blocked
                    self._breaker_topics.add(topic)
                    self._breaker_changed.set()
                    self._log.warning("subscription to %s: breaker %s", topic, sub.breaker.state)
            if (
                topic not in self._breaker_topics
                and topic in self._forwarded_hz
                and self._merged_hints(topic).max_hz != self._forwarded_hz[topic]
            ):
                # an adaptive throttle moved: the bridge may send less (or more)
                self._breaker_topics.add(topic)
                self._breaker_changed.set()

    async def _remove_subscription(self, sub: Subscription) -> None:
        sub.close()
        self._hints.pop(sub, None)
        subs = self._subs.get(sub.topic)
        if subs is None or sub not in subs:
            return
        subs.remove(sub)
        if not self.connected:
            if not subs:
                del self._subs[sub.topic]
                self._forwarded_hz.pop(sub.topic, None)
            return
        with anyio.CancelScope(shield=True), anyio.move_on_after(self._options.teardown_timeout):
            try:
                if subs:
                    await self._subscribe_at_bridge(sub.topic)
                else:
                    del self._subs[sub.topic]
                    self._forwarded_hz.pop(sub.topic, None)
                    await self._backend.unsubscribe(sub.topic)
            except ConnectError as exc:
                self._log.debug("unsubscribe from %s failed: %s", sub.topic, exc)

    # -- publishing ---------------------------------------------------------
    async def advertise(self, topic: str, schema: str, *, latch: bool = False) -> None:
        """Advertise ``topic`` with type ``schema`` ahead of the first publish,
        taking the bridge's set-up time out of the hot path. ``latch=True``
        (rosbridge) keeps the last message for subscribers that join later;
        the Foxglove protocol cannot (``NotSupportedError``)."""
        _check_name("topic", topic)
        _check_schema(schema)
        if not isinstance(latch, bool):
            raise TypeError("latch must be a bool")
        self._require_connected()
        await self._backend.advertise(topic, schema, latch=latch)

    async def unadvertise(self, topic: str) -> None:
        """Stop publishing ``topic``. A velocity topic still gets its zero
        Twist on teardown."""
        _check_name("topic", topic)
        self._require_connected()
        await self._backend.unadvertise(topic)

    async def publish(
        self,
        topic: str,
        schema: str,
        data: Mapping[str, Any],
        *,
        priority: Priority = "data",
        check_velocity: bool = True,
    ) -> None:
        """Publish ``data`` (a dict; missing fields are zero) on ``topic``.

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
        ``ValueError`` when ``data`` does not fit the schema."""
        _check_name("topic", topic)
        _check_schema(schema)
        if priority not in ("data", "control"):
            raise ValueError(f"priority must be 'data' or 'control', got {priority!r}")
        if not isinstance(data, Mapping):
            raise TypeError(f"data must be a mapping (dict), not {type(data).__name__}")
        if not isinstance(check_velocity, bool):
            raise TypeError("check_velocity must be a bool")
        self._require_connected()
        await self._check_publish(topic, schema, check_velocity)
        backend = self._backend
        ready = backend.advertised(topic)
        if ready is None or not same_type_name(ready, schema):
            await backend.advertise(topic, schema)  # the hot path skips this await
        try:
            message = backend.encode_publish(topic, data)
        except DecodeError as exc:
            raise ValueError(f"{topic}: {exc}") from exc
        if _is_velocity_type(schema):
            self._velocity[topic] = schema
        if priority == "control":
            # Queued, then written at once: not behind the writer's or the
            # reader's next turn. Control frames queued meanwhile go first.
            # Returns once this frame (or a newer value for the topic that
            # replaced it) is written; another task may be writing it.
            receipt = self._queue_control(topic, message)
            error: ConnectError | None
            try:
                await self._send_control()
            except ConnectError as exc:  # lost: before this frame's turn, or on it
                error = receipt.error if receipt.done.is_set() else exc
            else:
                await receipt.done.wait()
                error = receipt.error
            if error is not None:
                raise NotConnected(
                    f"disconnected: {error} (the control frame for {topic} was not sent)"
                ) from error
        else:
            await self._outbox.put_data(topic, message)

    async def _check_publish(self, topic: str, schema: str, check_velocity: bool) -> None:
        """The type checks of :meth:`publish` (``SchemaError``); nothing is
        sent unless resolving ``schema`` needs the server's definition. A
        passed check is remembered until the graph or the connection
        changes, so the hot path pays one set lookup."""
        backend = self._backend
        graph = self._topics.value
        seen = self._publish_checked_for
        if seen is None or seen[0] is not backend or seen[1] is not graph:
            self._publish_checked = set()
            self._publish_checked_for = (backend, graph)
        key = (topic, schema, check_velocity)
        if key in self._publish_checked:
            return
        self._apply_user_types(backend)
        velocity_topic = topic.endswith("cmd_vel") or topic in self._options.stop_topics
        resolved = backend.codecs.resolves(schema) or any(
            same_type_name(t.schema_name, schema) for t in graph
        )
        if not resolved and not (check_velocity and velocity_topic):
            # (a velocity topic refuses an unresolved type anyway: no round trip)
            resolved = await backend.fetch_definition(schema)
        if not resolved:
            raise SchemaError(
                f"unknown type {schema!r} for {topic}: no definition is bundled, the server "
                "offers none and none was registered (Client.register_type); misspelled?"
            )
        for info in graph:
            if (
                info.name == topic
                and info.schema_name
                and not same_type_name(info.schema_name, schema)
            ):
                raise SchemaError(
                    f"{topic} carries {info.schema_name!r} on the robot; publishing {schema!r} "
                    "there contradicts it"
                )
        if check_velocity and velocity_topic and not _is_velocity_type(schema):
            raise SchemaError(
                f"{topic} is a velocity topic and {schema!r} is not geometry_msgs/msg/Twist or "
                "TwistStamped: the robot would not obey it, nor stop on it "
                "(check_velocity=False, or rmb pub --no-velocity-check, sends it anyway)"
            )
        self._publish_checked.add(key)

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
        _check_schema(name)
        if not isinstance(definition, str | bytes):
            raise TypeError(f"definition must be str or bytes, not {type(definition).__name__}")
        if encoding not in ("ros2msg", "ros2idl", "ros2action"):
            raise ValueError(
                f"encoding must be 'ros2msg', 'ros2idl' or 'ros2action', got {encoding!r}"
            )
        scratch = CodecRegistry()
        for known, (known_encoding, text) in self._user_types.items():
            scratch.add_schema(known, known_encoding, text)
        scratch.add_schema(name, encoding, definition)
        if encoding == "ros2action":
            checked = [f"{name}_SendGoal_Request", f"{name}_GetResult_Response"]
            checked.append(f"{name}_FeedbackMessage")
        elif "/srv/" in name:
            checked = list(CodecRegistry.service_type_names(name))
        else:
            checked = [name]
        for each in checked:
            scratch.encoder(each, "cdr")  # every type it uses resolves
        self._user_types[name] = (encoding, definition)
        self._user_types_in = None
        self._publish_checked = set()
        self._apply_user_types(self._backend)

    def _apply_user_types(self, backend: Backend) -> None:
        if self._user_types and self._user_types_in is not backend:
            for name, (encoding, text) in self._user_types.items():
                backend.codecs.add_schema(name, encoding, text)
            self._user_types_in = backend

    async def publish_zero_twist(self, topic: str = "/cmd_vel", schema: str | None = None) -> None:
        """Publish a zero velocity at control priority. ``schema`` defaults to
        what this client already published there, else the advertised type,
        else ``geometry_msgs/msg/Twist``."""
        _check_name("topic", topic)
        if schema is None:
            schema = self._velocity_schema(topic)
        elif not _is_velocity_type(_check_schema(schema)):
            raise ValueError(f"schema must be Twist or TwistStamped, got {schema!r}")
        await self.publish(topic, schema, self._zero(schema), priority="control")

    # -- recording ----------------------------------------------------------
    def record(
        self,
        path: str | os.PathLike[str],
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
        on entering (``OSError``). See docs/recording.md."""
        from ._record import check_record_args, open_recording

        checked, wanted = check_record_args(path, topics, max_hz, compression)
        if not isinstance(adaptive, bool):
            raise TypeError("adaptive must be a bool")
        return open_recording(self, checked, wanted, max_hz, adaptive, compression)

    # -- services -----------------------------------------------------------
    async def call_service(
        self, name: str, request: Mapping[str, Any] | None = None, *, timeout: float | None = None
    ) -> Any:
        """Call service ``name`` with ``request`` (a dict; missing fields are
        zero) and return the decoded response (a dict).

        Raises ``ServiceError`` with the server's text when the call fails,
        ``ServiceTimeout`` when no answer came within ``timeout`` seconds
        (default ``options.service_timeout``), ``NotConnected`` when the
        connection is or goes away. A call never waits forever."""
        _check_name("service name", name)
        if request is not None and not isinstance(request, Mapping):
            raise TypeError(
                f"request must be a mapping (dict) or None, not {type(request).__name__}"
            )
        backend = self._backend
        return await self._request(
            name,
            lambda limit: backend.call_service(name, request, limit),
            timeout,
            slack=backend.wire_timeout_slack,
        )

    def serve(
        self,
        name: str,
        service_type: str,
        *,
        timeout: float = DEFAULT_SERVE_TIMEOUT,
        buffer: int = DEFAULT_SERVE_BUFFER,
    ) -> AbstractAsyncContextManager[ServiceRequests]:
        """Offer service ``name`` of type ``service_type``
        (``"pkg/srv/Name"``) to the ROS graph through the bridge; an async
        context manager yielding :class:`~ros_mobile_bridge.ServiceRequests`::

            async with robot.serve("/add", "example_interfaces/srv/AddTwoInts") as requests:
                async for req in requests:
                    await req.reply({"sum": req.args["a"] + req.args["b"]})

        Every call is answered exactly once: by ``req.reply(values)`` or
        ``req.fail(message)``, else with ``result: false`` and a reason when
        ``timeout`` seconds pass, when the loop moves on to the next request,
        or when the block ends; a call arriving while ``buffer`` unread ones
        wait is refused at once (``stats.overflowed``). Leaving the block
        unadvertises the service (shielded, within
        ``options.teardown_timeout``). After a reconnect it is advertised
        again; calls that were in flight on the lost connection are lost.

        rosbridge only: ``NotSupportedError`` over Foxglove (its protocol has
        no way to offer a service) and Zenoh. Arguments are checked here, at
        once (``ValueError`` / ``TypeError``); entering raises
        ``SchemaError`` when the bridge does not know the type,
        ``ServiceError`` when another client serves the name, ``ValueError``
        when this client serves it already."""
        _check_name("service name", name)
        _check_schema(service_type)
        if service_type.count("/") == 2 and service_type.split("/")[1] != "srv":
            raise ValueError(
                f"service_type must be a service type like 'pkg/srv/Name', got {service_type!r}"
            )
        limit = _check_timeout(timeout)
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
        self._require_connected()
        if name in self._served:
            raise ValueError(f"{name} is served by this client already")
        served = ServiceRequests(
            name,
            service_type,
            timeout=timeout,
            buffer=buffer,
            current=lambda: self._backend if self.connected else None,
            teardown_timeout=self._options.teardown_timeout,
            logger=self._log,
        )
        self._served[name] = served
        try:
            await self._backend.advertise_service(name, service_type, served)
        except BaseException:
            # the bridge may serve it though (sent, not confirmed): answer the
            # calls that came, then unadvertise (the bridge drops calls still
            # open when the service goes)
            self._served.pop(name, None)
            await self._end_serving(name, served, "the service could not be served")
            raise
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(served._expire, name=f"rmb-serve-{name}")
                try:
                    yield served
                finally:
                    tg.cancel_scope.cancel()
        finally:
            self._served.pop(name, None)
            await self._end_serving(name, served, "the service stopped serving")

    async def _end_serving(self, name: str, served: ServiceRequests, reason: str) -> None:
        """Answer what is open, then unadvertise ``name``: shielded, within
        ``options.teardown_timeout``, half of it at most for the answers so
        that the unadvertise always has the other half."""
        budget = self._options.teardown_timeout
        with anyio.CancelScope(shield=True), anyio.move_on_after(budget):
            await served._close(reason, budget / 2)
            if self.connected:
                try:
                    await self._backend.unadvertise_service(name)
                except RosBridgeError as exc:
                    self._log.debug("unadvertising %s failed: %s", name, exc)

    async def _request(
        self,
        what: str,
        call: Callable[[float], Awaitable[T]],
        timeout: float | None,
        *,
        slack: float = 0.0,
    ) -> T:
        """Run one correlated request under its deadline (``timeout`` or
        ``options.service_timeout``) and report its round trip to
        ``on_latency``. ``call`` gets the limit (a backend may forward it);
        the local deadline is ``slack`` later, so the server's own timeout
        answer arrives first. ``ServiceTimeout`` names ``what``."""
        limit = _check_timeout(timeout) or self._options.service_timeout
        self._require_connected()
        start = time.perf_counter()
        with anyio.move_on_after(limit + slack) as scope:
            result = await call(limit)
        if scope.cancelled_caught:
            raise ServiceTimeout(what, limit)
        self._options.report_latency((time.perf_counter() - start) * 1000.0)
        return result

    # -- parameters ---------------------------------------------------------

    async def get_parameters(
        self, names: Sequence[str], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Current values of the named parameters (names the server does not
        know are absent from the result)."""
        if isinstance(names, str) or not all(isinstance(n, str) for n in names):
            raise TypeError("names must be a sequence of str")
        names = list(names)
        return await self._request(
            "getParameters", lambda _limit: self._backend.get_parameters(names), timeout
        )

    async def list_parameters(self, *, timeout: float | None = None) -> dict[str, Any]:
        """Every parameter the server exposes, with its value."""
        return await self._request(
            "getParameters", lambda _limit: self._backend.get_parameters([]), timeout
        )

    async def set_parameters(
        self, values: Mapping[str, Any], *, timeout: float | None = None
    ) -> dict[str, Any]:
        """Set parameters; returns the values the server reports afterwards."""
        if not isinstance(values, Mapping) or not all(isinstance(k, str) for k in values):
            raise TypeError("values must be a mapping of parameter name to value")
        values = dict(values)
        return await self._request(
            "setParameters", lambda _limit: self._backend.set_parameters(values), timeout
        )

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
        self._require_connected()
        await self._backend.subscribe_parameters(wanted)
        for name in wanted:
            self._watched_parameters[name] = self._watched_parameters.get(name, 0) + 1

        async def updates() -> AsyncIterator[dict[str, Any]]:
            last: dict[str, Any] | None = None
            async for snapshot in self._parameters.watch():
                view = {n: snapshot[n] for n in wanted if n in snapshot}
                if view and view != last:
                    last = view
                    yield view

        iterator = updates()
        try:
            yield iterator
        finally:
            with (
                anyio.CancelScope(shield=True),
                anyio.move_on_after(self._options.teardown_timeout),
            ):
                await iterator.aclose()  # type: ignore[attr-defined]
                unwatched = []
                for name in wanted:
                    left = self._watched_parameters.get(name, 0) - 1
                    if left > 0:
                        self._watched_parameters[name] = left
                    else:
                        self._watched_parameters.pop(name, None)
                        unwatched.append(name)
                if self.connected and unwatched:
                    with contextlib.suppress(ConnectError):
                        await self._backend.unsubscribe_parameters(unwatched)

    # -- schemas ------------------------------------------------------------
    def schema_template(self, name: str) -> dict[str, Any]:
        """A zero-filled message of type ``name`` (fixed-size arrays filled),
        from the server's schemas or the bundled ROS 2 definitions."""
        return self._backend.codecs.template(_check_schema(name))

    def schema_definition(self, name: str) -> list[FieldDef]:
        """The fields of type ``name``, in order, with their types."""
        return self._backend.codecs.definition(_check_schema(name))

    # -- actions ------------------------------------------------------------
    @asynccontextmanager
    async def send_action_goal(
        self, action: str, action_type: str, goal: Mapping[str, Any]
    ) -> AsyncIterator[ActionGoal]:
        """Send ``goal`` to action server ``action`` (type ``action_type``,
        e.g. ``"test_msgs/action/Fibonacci"``); an async context manager
        yielding the :class:`~ros_mobile_bridge.ActionGoal`.

        Leaving the block before the goal ended cancels it (shielded, within
        ``options.teardown_timeout``). A lost connection fails the goal with
        reason ``"disconnected"``. ``NotSupportedError`` over Foxglove, whose
        protocol has no actions."""
        _check_name("action", action)
        _check_schema(action_type)
        if not isinstance(goal, Mapping):
            raise TypeError(f"goal must be a mapping (dict), not {type(goal).__name__}")
        self._require_connected()
        backend = self._backend
        goal_id: list[str] = []

        async def cancel() -> None:
            if goal_id and self._backend is backend and self.connected:
                await backend.cancel_action_goal(action, goal_id[0])

        handle = ActionGoal(action, cancel)
        goal_id.append(await backend.send_action_goal(action, action_type, dict(goal), handle))
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


class _SubscriptionContext:
    """What :meth:`Client.subscribe` returns: enter to subscribe, exit to
    unsubscribe (the bridge stops sending once no local subscriber is left)."""

    def __init__(self, client: Client, sub: Subscription, hints: SubscribeHints) -> None:
        self._client = client
        self._sub = sub
        self._hints = hints

    async def __aenter__(self) -> Subscription:
        await self._client._add_subscription(self._sub, self._hints)
        return self._sub

    async def __aexit__(self, *exc_info: object) -> None:
        await self._client._remove_subscription(self._sub)
