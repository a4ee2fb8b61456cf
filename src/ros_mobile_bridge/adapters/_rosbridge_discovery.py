"""Discovery over rosbridge: the graph's topics and services, polled through
the bridge's ``/rosapi/*`` services and bounded by the connection's limits.
A part of :class:`~._rosbridge.RosbridgeAdapter`, and its node list."""

from __future__ import annotations

import logging
from collections.abc import Awaitable, Callable
from typing import Any, Final

import anyio

from .._errors import ConnectError, NotConnected, ServiceError
from .._options import ClientOptions
from .._types import ServiceInfo, TopicEndpoints, TopicInfo
from ._rosbridge_calls import RosbridgeCalls
from ._seam import GraphChanged
from ._shared import EventSource

_EMPTY_RETRY_DELAY: Final = 0.25
_TYPE_LOOKUPS_PER_POLL: Final = 4
"""Service types looked up per discovery poll: a burst of rosapi calls makes
rosbridge_server_rs drop messages of busy topics (measured at 5 kHz)."""


class RosbridgeDiscovery:
    """The graph as ``/rosapi`` reports it: the topic and service tables,
    their polling (``options.discovery_interval``), the service types looked
    up a few per poll, and the ``max_channels`` / ``max_services`` bounds.
    Also the connection's node list (``Adapter.node_list``)."""

    def __init__(
        self,
        calls: RosbridgeCalls,
        options: ClientOptions,
        events: EventSource,
        resync: Callable[[], Awaitable[None]],
    ) -> None:
        """``resync`` brings every wanted subscription in line with the
        graph; each poll calls it."""
        self._rosapi = calls.rosapi
        self._options = options
        self._log: logging.Logger = options.logger
        self._events = events
        self._resync = resync
        self.topic_types: dict[str, str] = {}
        """Topic name -> type, from the last ``/rosapi/topics`` (replaced,
        not changed, by each poll)."""
        self.service_types: dict[str, str] = {}
        """Service name -> type (``""`` until looked up)."""
        self.works = False
        """Whether the last poll got an answer."""
        self._warned = False
        self._over_limit: set[str] = set()  # graph limits exceeded at the last poll

    @property
    def topics(self) -> list[TopicInfo]:
        return [TopicInfo(name, schema) for name, schema in sorted(self.topic_types.items())]

    @property
    def services(self) -> list[ServiceInfo]:
        return [ServiceInfo(name, schema) for name, schema in sorted(self.service_types.items())]

    async def nodes(self) -> list[str]:
        """The graph's nodes as ``/rosapi/nodes`` lists them (bounded by
        ``max_channels``, as the topic table is); ``ServiceError`` when the
        bridge offers no rosapi, ``TimeoutError`` after 5 s."""
        names = sorted(set(names_in(await self._rosapi("/rosapi/nodes"), "nodes")))
        return names[: self._options.max_channels]

    async def topic_endpoints(self, topic: str) -> TopicEndpoints:
        """``/rosapi/publishers`` and ``/rosapi/subscribers`` of ``topic``
        (node names); ``ServiceError`` when the bridge offers no rosapi."""
        args = {"topic": topic}
        pubs = names_in(await self._rosapi("/rosapi/publishers", args), "publishers")
        subs = names_in(await self._rosapi("/rosapi/subscribers", args), "subscribers")
        return TopicEndpoints(topic, tuple(sorted(pubs)), tuple(sorted(subs)))

    async def discover(self, *, first: bool = False) -> bool:
        """Poll the graph once; True when it changed. A failing rosapi is
        reported once and leaves the tables as they were."""
        try:
            answer = await self._rosapi("/rosapi/topics")
            if first and not names_in(answer, "topics"):
                await anyio.sleep(_EMPTY_RETRY_DELAY)  # a bridge that just started
                answer = await self._rosapi("/rosapi/topics")
            services = await self._rosapi("/rosapi/services")
        except (ServiceError, TimeoutError) as exc:
            if not self._warned:
                self._warned = True
                self._log.warning(
                    "discovery through /rosapi failed (%s): topic and service lists stay empty;"
                    " subscribe with schema= and publish still work",
                    exc,
                )
            self.works = False
            return False
        self.works = True
        names = self._bounded(names_in(answer, "topics"), "channel_limit", "topics")
        types = names_in(answer, "types")
        topics = {n: (types[i] if i < len(types) else "") for i, n in enumerate(names)}
        service_names = self._bounded(names_in(services, "services"), "service_limit", "services")
        old_services = self.service_types
        new_services = {n: old_services.get(n, "") for n in service_names}
        changed = topics != self.topic_types or new_services != old_services
        self.topic_types = topics
        self.service_types = new_services
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

    async def service_type(self, name: str) -> str | None:
        """The type of service ``name``: the graph's, else asked of
        ``/rosapi/service_type`` now (and kept for the graph); None when the
        bridge does not say (no such service, no rosapi)."""
        known = self.service_types.get(name)
        if known:
            return known
        try:
            answer = await self._rosapi("/rosapi/service_type", {"service": name})
        except (ServiceError, TimeoutError):
            return None
        schema = answer.get("type") if isinstance(answer, dict) else None
        if not isinstance(schema, str) or not schema:
            return None
        if name in self.service_types:
            self.service_types[name] = schema
        return schema

    async def _lookup_service_types(self) -> bool:
        unknown = [n for n, t in self.service_types.items() if not t][:_TYPE_LOOKUPS_PER_POLL]
        changed = False
        for name in unknown:
            try:
                answer = await self._rosapi("/rosapi/service_type", {"service": name})
            except (ServiceError, TimeoutError):
                continue
            schema = answer.get("type") if isinstance(answer, dict) else None
            if isinstance(schema, str) and schema and name in self.service_types:
                self.service_types[name] = schema
                changed = True
        return changed

    async def poll(self) -> None:
        """Keep the graph current: right away (after a (re)connect), then every
        ``options.discovery_interval``."""
        interval = self._options.discovery_interval
        first = True
        try:
            while True:
                changed = await self.discover() if not first else False
                first = False
                changed |= await self._lookup_service_types()
                if changed:
                    self._events.emit(GraphChanged(self.topics, self.services))
                await self._resync()
                self._events.post()
                await anyio.sleep(interval)
        except (ConnectError, NotConnected):
            return  # the reader reports the loss


def names_in(answer: Any, key: str) -> list[str]:
    """The strings listed under ``key`` in a rosapi answer (none when it is
    not a list)."""
    values = answer.get(key) if isinstance(answer, dict) else None
    if not isinstance(values, list):
        return []
    return [v for v in values if isinstance(v, str)]
