"""The router: what the adapter's reader hands up goes to the subscriptions
and the client's watchable state (topics, services, parameters, rejection
counts), and what the subscriptions want goes down to the bridge (subscribe,
unsubscribe, the forwarded rate, the circuit breaker's verdict). It is the
adapter's :class:`~..adapters.EventSink`; the connection tells it which
adapter is current."""

from __future__ import annotations

import contextlib
import logging
import time
from collections.abc import AsyncIterator, Callable, Mapping
from dataclasses import dataclass
from functools import partial
from typing import Any, Final

import anyio
import anyio.lowlevel

from .._checks import nearest_hint
from .._errors import ConnectError
from .._options import ClientOptions
from .._types import (
    Compression,
    Dispatch,
    PlaybackState,
    SaveBandwidth,
    ServerStatus,
    ServiceInfo,
    Status,
    StatusRemoved,
    TopicInfo,
)
from ..adapters import (
    Adapter,
    Event,
    GraphChanged,
    ParameterValues,
    Rejected,
    Replayed,
    ServerClock,
    SubscribeHints,
    TopicState,
    require,
)
from ..flow import (
    AdaptiveThrottle,
    Bucket,
    Feed,
    FrameQueue,
    LagMonitor,
    RawFrame,
    Subscription,
    ThrottleMode,
    Watchable,
    current_monitor,
)
from ._outbound import Outbound
from ._rejection_log import RejectionLog

__all__ = ["Route", "Router"]

_READER_YIELD_EVERY: Final = 64
"""Events handed over between two turns the reader gives the consumers."""


@dataclass(eq=False, slots=True)
class Route:
    """One local subscription as the router keeps it: the user's
    :class:`Subscription`, the queue frames go to, its adaptive throttle and
    what the bridge is told."""

    sub: Subscription[Any]
    queue: FrameQueue
    throttle: AdaptiveThrottle | None
    hints: SubscribeHints
    save_bandwidth: SaveBandwidth = False
    seen_interval: float | None = None
    """Its throttle's interval at the last reliability tick (None: not yet)."""


class Router:
    """Events in, subscriptions and watchable state out; see the module."""

    def __init__(
        self,
        adapter: Adapter,
        options: ClientOptions,
        presets: Mapping[ThrottleMode, tuple[Bucket, ...]],
        status: Watchable[Status],
        outbound: Outbound,
    ) -> None:
        self.adapter = adapter
        """The current connection (the lost one until a reconnect restores)."""
        self._options = options
        self._log: logging.Logger = options.logger
        self.logger = self._log
        """The client's logger (``options.logger``)."""
        self._presets = presets
        # a fixed mode or the user's callable, read per message (see AdaptiveThrottle)
        self._mode: ThrottleMode | Callable[[], ThrottleMode] = options.throttle_mode
        self._status = status
        self._outbound = outbound
        self.topics: Watchable[list[TopicInfo]] = Watchable(adapter.topics)
        self.services: Watchable[list[ServiceInfo]] = Watchable(adapter.services)
        self.parameters: Watchable[dict[str, Any]] = Watchable({})
        self.server_time: Watchable[int | None] = Watchable(None)
        self.server_status: Feed[ServerStatus | StatusRemoved] = Feed()
        self.playback: Watchable[PlaybackState | None] = Watchable(None)
        self._rejections = RejectionLog(self._log)
        self._routes: dict[str, list[Route]] = {}
        self._unoffered: dict[Route, float] = {}  # route -> when to warn (unknown_topic_warning)
        self._offers: dict[str, list[Callable[[RawFrame], None]]] = {}  # the hot path's table
        self._watched_parameters: dict[str, int] = {}
        self._inbound = 0
        self._breaker_changed = anyio.Event()  # set by the tick when a breaker changed
        self._breaker_topics: set[str] = set()  # topics to subscribe again at the bridge
        # the rates each topic's bridge subscription asks: (max_hz, pause_hz)
        self._forwarded_hz: dict[str, tuple[float | None, float | None]] = {}
        # the reliability tick while run_reliability runs, the loop's monitor,
        # and its key there while registered (see _sync_tick)
        self._tick: Callable[[], None] | None = None
        self._tick_monitor: LagMonitor | None = None
        self._tick_key: int | None = None

    @property
    def _connected(self) -> bool:
        return self._status.value == "connected"

    # -- the sink (reader task) ------------------------------------------------
    async def deliver(self, events: list[Event]) -> None:
        """:meth:`EventSink.deliver`: before each event, queued control frames
        are written; every 64 events the consumers get a turn, so a burst
        read in one go does not overflow their queues before they wake."""
        outbox = self._outbound.outbox
        offers = self._offers
        if not events:
            if outbox.has_control:
                await self._send_control()
            return
        for event in events:
            if outbox.has_control:
                await self._send_control()
            if type(event) is RawFrame:
                targets = offers.get(event.topic)
                if targets:
                    for offer in targets:
                        offer(event)
            else:
                self.post(event)
            self._inbound += 1
            if self._inbound >= _READER_YIELD_EVERY:
                self._inbound = 0
                await anyio.lowlevel.checkpoint()

    def deliver_now(self, frame: RawFrame) -> bool:
        """:meth:`EventSink.deliver_now`: the frame to its subscriptions at
        once, unless control frames wait to be written (the reader's
        :meth:`deliver` writes them first)."""
        if self._outbound.outbox.has_control:
            return False
        targets = self._offers.get(frame.topic)
        if targets:
            for offer in targets:
                offer(frame)
        return True

    def quiet_until(self, now: float) -> float:
        """:meth:`EventSink.quiet_until`: the earliest
        :meth:`FrameQueue.quiet_until` of this client's subscriptions (0.0
        with none, or when one can take a frame now)."""
        until = 0.0
        for routes in self._routes.values():
            for route in routes:
                t = route.queue.quiet_until(now)
                if t <= now:
                    return 0.0
                if t < until or not until:
                    until = t
        return until

    async def _send_control(self) -> None:
        with contextlib.suppress(ConnectError):  # the reader's next read reports it
            await self._outbound.send_control()

    def post(self, event: Event) -> None:
        """:meth:`EventSink.post`: apply one event at once."""
        if type(event) is RawFrame:
            for offer in self._offers.get(event.topic, ()):
                offer(event)
        elif type(event) is GraphChanged:
            self.topics.set(event.topics)
            self.services.set(event.services)
        elif type(event) is TopicState:
            self.set_topic_state(event.topic, event.active)
        elif type(event) is ParameterValues:
            merged = dict(self.parameters.value)
            merged.update(event.values)
            self.parameters.set(merged)
        elif type(event) is Rejected:
            self._rejected(event)
        elif type(event) is Replayed:
            for route in self._routes.get(event.topic, ()):
                route.queue.replayed(event.size)
        elif type(event) is ServerClock:
            self.server_time.set(event.time_ns)
        elif type(event) is ServerStatus or type(event) is StatusRemoved:
            self.server_status.publish(event)
        elif type(event) is PlaybackState:
            self.playback.set(event)

    def set_topic_state(self, topic: str, active: bool) -> None:
        """The server now carries ``topic`` to us, or not."""
        for route in self._routes.get(topic, ()):
            route.queue.set_state("active" if active else "pending")

    def _rejected(self, event: Rejected) -> None:
        """Counted per reason (see :attr:`rejections`) and logged at a
        bounded rate (see :mod:`._rejection_log`)."""
        self._rejections.add(event.reason, event.detail, event.count)

    @property
    def rejections(self) -> dict[str, int]:
        """How many inbound frames were skipped or refused, per reason, over
        the client's life (a copy)."""
        return self._rejections.counts

    def graph_now(self) -> None:
        """Take the current adapter's topic and service lists."""
        self.topics.set(self.adapter.topics)
        self.services.set(self.adapter.services)

    # -- subscriptions ---------------------------------------------------------
    def route(
        self,
        topic: str,
        *,
        max_hz: float | None,
        adaptive: bool,
        dispatch: Dispatch,
        schema: str | None,
        buffer: int | None,
        compression: Compression | None,
        decode: bool = True,
        save_bandwidth: SaveBandwidth = False,
        want: type | None = None,
    ) -> Route:
        """Build one subscription's pipeline (throttle, queue, breaker); not
        routed until :meth:`add`. The queue checks its own arguments.
        ``want``: the message class the subscription delivers, or None."""
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
        sub: Subscription[Any] = Subscription(
            topic,
            queue,
            logger=self._log,
            throttle=throttle,
            breaker=breaker,
            decode=decode,
            want=want,
        )
        hints = SubscribeHints(max_hz=max_hz, schema=schema, compression=compression)
        return Route(sub, queue, throttle, hints, save_bandwidth)

    def _rate_for(self, route: Route) -> float | None:
        """The rate the bridge need not exceed for ``route`` (None: all): its
        ``max_hz``, tightened by its adaptive throttle's current interval.
        rosbridge gets it as ``throttle_rate``; the other bridges have no
        such option."""
        hz = route.hints.max_hz
        throttle = route.throttle
        if throttle is not None and (interval := throttle.interval) > 0.0:
            adaptive = 1.0 / interval
            hz = adaptive if hz is None else min(hz, adaptive)
        return hz

    def _pause_for(self, route: Route) -> float | None:
        """The rate at which the bridge may resume sending after each message
        for ``route`` (None: it must send every message): ``save_bandwidth``
        follows the ``max_hz`` cap, ``"adaptive"`` also the adaptive
        throttle's interval where it is tighter."""
        mode = route.save_bandwidth
        if mode is False:
            return None
        return self._rate_for(route) if mode == "adaptive" else route.hints.max_hz

    def _merged_hints(self, topic: str) -> SubscribeHints:
        routes = [r for r in self._routes.get(topic, ()) if not r.queue.blocked]
        caps = [self._rate_for(r) for r in routes]
        loosest = None if not caps or None in caps else max(c for c in caps if c is not None)
        pauses = [self._pause_for(r) for r in routes]
        pause = None if not pauses or None in pauses else max(p for p in pauses if p is not None)
        schema = next((r.hints.schema for r in routes if r.hints.schema), None)
        compression = next((r.hints.compression for r in routes if r.hints.compression), None)
        return SubscribeHints(
            max_hz=loosest, schema=schema, compression=compression, pause_hz=pause
        )

    async def _subscribe_at_bridge(self, topic: str) -> None:
        """Subscribe (again) at the bridge with the merged hints of the local
        subscriptions, and remember the rate forwarded."""
        hints = self._merged_hints(topic)
        self._forwarded_hz[topic] = (hints.max_hz, hints.pause_hz)
        await self.adapter.subscribe(topic, hints)

    def _link(self, route: Route) -> None:
        topic = route.sub.topic
        self._routes.setdefault(topic, []).append(route)
        self._offers.setdefault(topic, []).append(route.queue.offer)
        self._sync_tick()

    def _unlink(self, route: Route) -> list[Route] | None:
        """Stop routing to ``route``; the topic's routes left (None when it
        was not routed)."""
        topic = route.sub.topic
        routes = self._routes.get(topic)
        if routes is None or route not in routes:
            return None
        routes.remove(route)
        self._offers[topic] = [r.queue.offer for r in routes]
        if not routes:
            del self._routes[topic]
            del self._offers[topic]
            self._forwarded_hz.pop(topic, None)
            self._sync_tick()
        return routes

    async def add(self, route: Route) -> None:
        """Route ``route`` and have the bridge send its topic. While the
        connection is being re-established it stays pending: the reconnect
        subscribes it. ``NotConnected`` when there is no connection."""
        reconnecting = self._status.value == "reconnecting"
        self._link(route)
        if reconnecting:
            return
        try:
            await self._subscribe_at_bridge(route.sub.topic)
        except BaseException:
            await self.remove(route)
            raise
        if self.adapter.topic_active(route.sub.topic):
            route.queue.set_state("active")
        grace = self._options.unknown_topic_warning
        if grace is not None and not self._offered(route.sub.topic):
            self._unoffered[route] = time.monotonic() + grace

    async def remove(self, route: Route) -> None:
        """Stop ``route``; the bridge stops sending once no local
        subscription wants the topic (shielded, within the teardown
        deadline)."""
        route.sub.close()
        self._unoffered.pop(route, None)
        topic = route.sub.topic
        left = self._unlink(route)
        if left is None or not self._connected:
            return
        with anyio.CancelScope(shield=True), anyio.move_on_after(self._options.teardown_timeout):
            try:
                if left:
                    await self._subscribe_at_bridge(topic)
                else:
                    await self.adapter.unsubscribe(topic)
            except ConnectError as exc:
                self._log.debug("unsubscribe from %s failed: %s", topic, exc)

    async def sync_topic(self, topic: str) -> None:
        """Make the bridge carry ``topic`` exactly when a local subscription
        whose breaker is not tripped wants it."""
        adapter = self.adapter
        if any(not r.queue.blocked for r in self._routes.get(topic, ())):
            await self._subscribe_at_bridge(topic)
            if adapter.topic_active(topic):
                self.set_topic_state(topic, True)
        else:
            self._forwarded_hz.pop(topic, None)
            await adapter.unsubscribe(topic)
            self.set_topic_state(topic, False)

    async def restore(self) -> None:
        """On a fresh connection (:attr:`adapter`): the graph, every topic
        wanted and the parameter watches."""
        self.graph_now()
        for topic in list(self._routes):
            await self.sync_topic(topic)
        parameters = self.adapter.parameters
        if self._watched_parameters and parameters is not None:
            # (a server restarted without parameters: the watches wait)
            await parameters.subscribe_parameters(sorted(self._watched_parameters))

    def connection_lost(self) -> None:
        """Every subscription is pending again; breaker timers die with the
        connection."""
        for topic, routes in self._routes.items():
            self.set_topic_state(topic, False)
            for route in routes:
                route.sub.breaker.reset()
                route.queue.blocked = False

    def fail_all(self, error: Exception) -> None:
        """The connection is gone for good: every subscription raises
        ``error`` once its queued frames are consumed."""
        for routes in self._routes.values():
            for route in routes:
                route.queue.fail(error)

    def close(self) -> None:
        """The client is closed: subscriptions end after their queued frames,
        the watchable state stops."""
        for routes in self._routes.values():
            for route in routes:
                route.sub.close()
        self._rejections.flush()
        self.topics.close()
        self.services.close()
        self.parameters.close()
        self.server_time.close()
        self.server_status.close()
        self.playback.close()

    # -- parameters ------------------------------------------------------------
    @contextlib.asynccontextmanager
    async def watch_parameters(self, names: list[str]) -> AsyncIterator[None]:
        """Keep ``names`` watched at the bridge (counted per name, restored
        after a reconnect) for the block."""
        adapter = self.adapter
        await require(adapter.parameters, "parameters", adapter.protocol).subscribe_parameters(
            names
        )
        for name in names:
            self._watched_parameters[name] = self._watched_parameters.get(name, 0) + 1
        try:
            yield
        finally:
            unwatched = []
            for name in names:
                left = self._watched_parameters.get(name, 0) - 1
                if left > 0:
                    self._watched_parameters[name] = left
                else:
                    self._watched_parameters.pop(name, None)
                    unwatched.append(name)
            parameters = self.adapter.parameters
            if self._connected and unwatched and parameters is not None:
                with contextlib.suppress(ConnectError):
                    await parameters.unsubscribe_parameters(unwatched)

    # -- reliability -----------------------------------------------------------
    async def run_reliability(self) -> None:
        """Apply breaker and forwarded-rate changes at the bridge. The checks
        run in :meth:`_reliability_tick`, which the event loop's shared lag
        sampler calls every 200 ms for every client on the loop that has a
        subscription (one wake-up per loop, not one per client); this task
        wakes only when a breaker changed state and the bridge must stop or
        resume sending a topic."""
        monitor = current_monitor()
        self._tick = partial(self._reliability_tick, monitor)
        self._tick_monitor = monitor
        self._sync_tick()
        try:
            while True:
                await self._breaker_changed.wait()
                self._breaker_changed = anyio.Event()
                topics, self._breaker_topics = self._breaker_topics, set()
                for topic in sorted(topics):
                    if topic not in self._routes or not self._connected:
                        continue
                    try:
                        await self.sync_topic(topic)
                    except ConnectError as exc:
                        self._log.debug("bridge change on %s not applied: %s", topic, exc)
                    except Exception:  # a bug must not take the user's program down
                        self._log.exception("bridge change on %s failed", topic)
        finally:
            self._tick = None
            self._sync_tick()

    def _sync_tick(self) -> None:
        """Keep the reliability tick registered with the loop's shared
        sampler exactly while :meth:`run_reliability` runs and a subscription
        is routed: with none the tick has nothing to do, so a thousand idle
        clients on a loop add nothing to its ticks."""
        monitor = self._tick_monitor
        if monitor is None:
            return
        key = self._tick_key
        if self._tick is not None and self._routes:
            if key is None:
                self._tick_key = monitor.add_tick(self._tick)
        elif key is not None:
            self._tick_key = None
            monitor.remove_tick(key)

    def _offered(self, topic: str) -> bool:
        return any(info.name == topic for info in self.topics.value)

    def _warn_unoffered(self) -> None:
        """One WARNING per subscription still waiting, past
        ``unknown_topic_warning``, for a topic the robot does not offer
        (nothing once it is offered, active or has delivered)."""
        now = time.monotonic()
        for route, when in list(self._unoffered.items()):
            topic = route.sub.topic
            if route.queue.state == "active" or route.queue.received or self._offered(topic):
                del self._unoffered[route]
            elif now >= when:
                del self._unoffered[route]
                known = sorted(info.name for info in self.topics.value)
                self._log.warning(
                    "no message on %s after %g s: the robot does not offer it%s",
                    topic,
                    self._options.unknown_topic_warning,
                    nearest_hint(topic, known),
                )

    def _reliability_tick(self, monitor: LagMonitor) -> None:
        """Every 200 ms (see :meth:`run_reliability`): refresh each adaptive
        subscription's throttle, feed its breaker the lag, and note the
        topics whose breakers changed (tripped: the bridge stops sending;
        half-open or closed: it sends again) or whose forwarded rate moved
        with an adaptive throttle (rosbridge's ``throttle_rate``)."""
        if not self._routes or not self._connected:
            return
        if self._unoffered:
            self._warn_unoffered()
        lag = monitor.recurring_lag_ms()  # the loop's monitor, not looked up per client
        policy = self._options.breaker
        for topic, routes in self._routes.items():
            moved = False  # an adaptive throttle's interval changed since the last tick
            for route in routes:
                breaker = route.sub.breaker
                throttle = route.throttle
                if throttle is not None:
                    if policy is not None:
                        throttle.interval_s()  # refresh at_deepest
                        breaker.observe(lag, throttle.at_deepest)
                    else:
                        breaker.poll()
                    if throttle.interval != route.seen_interval:
                        moved = True
                else:
                    breaker.poll()
                blocked = breaker.state in ("tripped_auto", "tripped_manual")
                if blocked != route.queue.blocked:
                    route.queue.blocked = blocked
                    self._breaker_topics.add(topic)
                    self._breaker_changed.set()
                    self._log.warning("subscription to %s: breaker %s", topic, breaker.state)
            if moved and topic not in self._breaker_topics and topic in self._forwarded_hz:
                # an adaptive throttle moved: the bridge may send less (or
                # more); compared only then (merging the hints costs more
                # than the rest of the tick)
                for route in routes:
                    if route.throttle is not None:
                        route.seen_interval = route.throttle.interval
                hints = self._merged_hints(topic)
                if (hints.max_hz, hints.pause_hz) != self._forwarded_hz[topic]:
                    self._breaker_topics.add(topic)
                    self._breaker_changed.set()
