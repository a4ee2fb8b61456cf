"""Discovery over rosbridge: the graph's topics and services, polled through
the bridge's ``/rosapi/*`` services and bounded by the connection's limits.
A part of :class:`~._rosbridge.RosbridgeAdapter`."""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import Any, Final

import anyio

from .._errors import ConnectError, NotConnected, ServiceError
from .._options import ClientOptions
from .._types import ServiceInfo, TopicInfo
from ._seam import GraphChanged, SubscribeHints
from ._shared import EventSource

_INTERNAL_TIMEOUT: Final = 5.0
"""Seconds for the adapter's own rosapi requests (discovery, parameters)."""
_EMPTY_RETRY_DELAY: Final = 0.25
_TYPE_LOOKUPS_PER_POLL: Final = 4
"""Service types looked up per discovery poll: a burst of rosapi calls makes
rosbridge_server_rs drop messages of busy topics (measured at 5 kHz)."""


class RosbridgeDiscovery:
    """The graph as ``/rosapi`` reports it: the topic and service tables,
    their polling (``options.discovery_interval``), the service types looked
    up a few per poll, and the ``max_channels`` / ``max_services`` bounds. The
    adapter owns the state and helpers declared here."""

    _options: ClientOptions
    _log: logging.Logger
    _topics: dict[str, str]  # name -> type, from /rosapi/topics
    _services: dict[str, str]  # name -> type ("" until looked up)
    _wanted: dict[str, SubscribeHints]
    _rosapi_warned: bool
    _discovery_ok: bool
    _over_limit: set[str]  # graph limits exceeded at the last poll
    _rosapi: Callable[..., Awaitable[Any]]
    _sync: Callable[[str], Awaitable[None]]
    _events: EventSource

    @property
    def topics(self) -> list[TopicInfo]:
        return [TopicInfo(name, schema) for name, schema in sorted(self._topics.items())]

    @property
    def services(self) -> list[ServiceInfo]:
        return [ServiceInfo(name, schema) for name, schema in sorted(self._services.items())]

    async def nodes(self) -> list[str]:
        """The graph's nodes as ``/rosapi/nodes`` lists them (bounded by
        ``max_channels``, as the topic table is); ``ServiceError`` when the
        bridge offers no rosapi, ``TimeoutError`` after 5 s."""
        names = sorted(set(_names(await self._rosapi("/rosapi/nodes"), "nodes")))
        return names[: self._options.max_channels]

    async def _discover(self, *, first: bool = False) -> bool:
        """Poll the graph once; True when it changed. A failing rosapi is
        reported once and leaves the tables as they were."""
        try:
            answer = await self._rosapi("/rosapi/topics")
            if first and not _names(answer, "topics"):
                await anyio.sleep(_EMPTY_RETRY_DELAY)  # a bridge that just started
                answer = await self._rosapi("/rosapi/topics")
            services = await self._rosapi("/rosapi/services")
        except (ServiceError, TimeoutError) as exc:
            if not self._rosapi_warned:
                self._rosapi_warned = True
                self._log.warning(
                    "discovery through /rosapi failed (%s): topic and service lists stay empty;"
                    " subscribe with schema= and publish still work",
                    exc,
                )
            self._discovery_ok = False
            return False
        self._discovery_ok = True
        names = self._bounded(_names(answer, "topics"), "channel_limit", "topics")
        types = _names(answer, "types")
        topics = {n: (types[i] if i < len(types) else "") for i, n in enumerate(names)}
        service_names = self._bounded(_names(services, "services"), "service_limit", "services")
        old_services = self._services
        new_services = {n: old_services.get(n, "") for n in service_names}
        changed = topics != self._topics or new_services != self._services
        self._topics = topics
        self._services = new_services
        return changed

    def _bounded(self, names: list[str], reason: str, what: str) -> list[str]:
        """The first ``max_channels`` / ``max_services`` names; more are a
        rejection, reported when the graph first exceeds the bound (not on
        every poll while it stays over)."""
        limit = (
            self._options.max_channels if reason == "channel_limit" else self._options.max_services
        )
        if len(names) <= limit:
            self._over_limit.discard(reason)
            return names
        if reason not in self._over_limit:
            self._over_limit.add(reason)
            detail = (
                f"/rosapi/{what}: {len(names) - limit} of {len(names)} {what} refused: the "
                f"connection keeps at most {limit}"
            )
            self._events.reject(reason, detail)
        return names[:limit]

    async def _lookup_service_types(self) -> bool:
        unknown = [n for n, t in self._services.items() if not t][:_TYPE_LOOKUPS_PER_POLL]
        changed = False
        for name in unknown:
            try:
                answer = await self._rosapi("/rosapi/service_type", {"service": name})
            except (ServiceError, TimeoutError):
                continue
            schema = answer.get("type") if isinstance(answer, dict) else None
            if isinstance(schema, str) and schema and name in self._services:
                self._services[name] = schema
                changed = True
        return changed

    async def _poll_discovery(self) -> None:
        """Keep the graph current: right away (after a (re)connect), then every
        ``options.discovery_interval``."""
        interval = self._options.discovery_interval
        first = True
        try:
            while True:
                changed = await self._discover() if not first else False
                first = False
                changed |= await self._lookup_service_types()
                if changed:
                    self._events.emit(GraphChanged(self.topics, self.services))
                for topic in list(self._wanted):
                    await self._sync(topic)
                self._events.post()
                await anyio.sleep(interval)
        except (ConnectError, NotConnected):
            return  # the reader reports the loss


def _names(answer: Any, key: str) -> list[str]:
    values = answer.get(key) if isinstance(answer, dict) else None
    if not isinstance(values, list):
        return []
    return [v for v in values if isinstance(v, str)]
