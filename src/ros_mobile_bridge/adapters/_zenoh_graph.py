"""The ROS graph of one Zenoh connection, as rmw_zenoh's liveliness tokens
under ``@ros2_lv/<domain>/`` tell it: the tokens alive now, keyed by the
whole token (node and entity ids restart at 0 in every process), the topic
and service lists built from them, and the lookups the other parts of
:class:`~._zenoh.ZenohAdapter` make in them. It is also the connection's
node list part (``Adapter.node_list``).

The adapter's core feeds it (:meth:`ZenohGraph.on_token` for every
liveliness change, :meth:`ZenohGraph.rebuild` after a batch that changed
it); the graph itself only counts what it refuses."""

from __future__ import annotations

from .._types import ServiceInfo, TopicEndpoints, TopicInfo
from ..codec import same_type_name
from ..wire import rmw_zenoh as rz
from ._shared import EventSource

__all__ = ["ZenohGraph"]


class ZenohGraph:
    """The graph's tokens and what is read from them (see the module
    docstring); :meth:`nodes` makes it a :class:`~._seam.NodeLister`."""

    def __init__(self, domain: int, max_tokens: int, events: EventSource, own_node: str) -> None:
        """``max_tokens`` bounds the tokens kept (``options.max_channels``);
        ``own_node`` is this client's node token, left out of :meth:`nodes`."""
        self._domain = domain
        self._max_tokens = max_tokens
        self._events = events
        self._own_node = own_node
        self.tokens: dict[str, rz.Token] = {}
        """The live tokens of this domain, by key."""
        self.topic_infos: list[TopicInfo] = []
        self.service_infos: list[ServiceInfo] = []
        self.publishers_of: dict[str, int] = {}
        """Topic -> the publisher tokens seen for it (a topic is active
        while it has one)."""

    def on_token(self, key: str, alive: bool) -> bool:
        """Follow one liveliness change; True when the graph changed. A
        malformed token, or one past the bound, is counted and ignored."""
        if not alive:
            return self.tokens.pop(key, None) is not None
        if key in self.tokens:
            return False
        try:
            token = rz.parse_token(key)
        except rz.MalformedKey as exc:
            self._events.reject("malformed_token", f"{key}: {exc}")
            return False
        if token.domain != self._domain:
            return False
        if len(self.tokens) >= self._max_tokens:
            self._events.reject("channel_limit", f"more than {self._max_tokens} graph tokens")
            return False
        self.tokens[key] = token
        return True

    def rebuild(self) -> dict[str, str]:
        """Build the topic and service lists and :attr:`publishers_of` from
        the tokens; returns every topic's type (a publisher's wins)."""
        topics: dict[str, str] = {}
        publishers: dict[str, int] = {}
        services: dict[str, str] = {}
        for token in self.tokens.values():
            if token.name is None or token.type_name is None:
                continue
            if token.kind in (rz.EntityKind.PUBLISHER, rz.EntityKind.SUBSCRIPTION):
                if token.kind is rz.EntityKind.PUBLISHER or token.name not in topics:
                    topics[token.name] = token.type_name
                if token.kind is rz.EntityKind.PUBLISHER:
                    publishers[token.name] = publishers.get(token.name, 0) + 1
            elif token.kind is rz.EntityKind.SERVICE:
                services[token.name] = token.type_name
        self.topic_infos = [TopicInfo(n, t, "cdr") for n, t in sorted(topics.items())]
        self.service_infos = [ServiceInfo(n, t) for n, t in sorted(services.items())]
        self.publishers_of = publishers
        return topics

    # -- lookups ----------------------------------------------------------------------------
    def topic_type(self, topic: str) -> str | None:
        for info in self.topic_infos:
            if info.name == topic:
                return info.schema_name
        return None

    def service_type(self, name: str) -> str | None:
        """The type of the service ``name`` some node serves, or None."""
        for info in self.service_infos:
            if info.name == name:
                return info.type
        return None

    def graph_hash(self, name: str, kinds: tuple[rz.EntityKind, ...]) -> tuple[str, str] | None:
        """``(type, hash)`` of the entity ``name`` of one of ``kinds`` in the graph."""
        for token in self.tokens.values():
            if token.name == name and token.kind in kinds and token.type_name and token.type_hash:
                return token.type_name, token.type_hash
        return None

    def announced(self, schema: str) -> tuple[str, str] | None:
        """(type, hash) of a type named ``schema`` in the graph's tokens."""
        for token in self.tokens.values():
            if token.type_name and token.type_hash and same_type_name(token.type_name, schema):
                return token.type_name, token.type_hash
        return None

    def offered_qos(self, topic: str) -> list[rz.Qos]:
        """The QoS of each live publisher of ``topic``."""
        return [
            token.qos
            for token in self.tokens.values()
            if token.kind is rz.EntityKind.PUBLISHER and token.name == topic and token.qos
        ]

    async def nodes(self) -> list[str]:
        """The nodes whose liveliness tokens (``NN``) are alive on this
        domain, ours left out; bounded as the graph is (``max_channels``
        tokens)."""
        names = {
            f"{token.namespace.rstrip('/')}/{token.node_name}"
            for key, token in self.tokens.items()
            if token.kind is rz.EntityKind.NODE and key != self._own_node
        }
        return sorted(names)

    async def topic_endpoints(self, topic: str) -> TopicEndpoints:
        """The nodes whose publisher and subscription tokens name ``topic``
        (this client's own entities included: they are on the graph)."""
        ends: dict[rz.EntityKind, set[str]] = {
            rz.EntityKind.PUBLISHER: set(),
            rz.EntityKind.SUBSCRIPTION: set(),
        }
        for token in self.tokens.values():
            if token.name == topic and token.kind in ends:
                ends[token.kind].add(f"{token.namespace.rstrip('/')}/{token.node_name}")
        pubs, subs = ends[rz.EntityKind.PUBLISHER], ends[rz.EntityKind.SUBSCRIPTION]
        return TopicEndpoints(topic, tuple(sorted(pubs)), tuple(sorted(subs)))
