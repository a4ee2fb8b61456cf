"""Transient-local (latched) topics over Zenoh (:class:`ZenohLatched`, a part
of :class:`~._zenoh.ZenohAdapter`): the history a transient-local publisher
keeps, fetched for our subscriptions, and kept by our latched publishers for
late joiners, in the forms released ``rmw_zenoh_cpp`` versions use.

What rmw_zenoh does, read from ``rmw_publisher_data.cpp`` and
``rmw_subscription_data.cpp`` at every Jazzy, Kilted and Rolling release tag
of its release repository (the facts, not the code):

* **Publication cache** (Jazzy 0.2.0 and 0.2.1, Rolling 0.3.0 and 0.3.1;
  Humble 0.1.0 and 0.1.1). A transient-local publisher also declares zenoh-ext's
  ``PublicationCache`` on its data key, with history = the QoS depth, a
  *complete* queryable and the queryable prefix = its session's zid: the
  queryable is ``<zid>/<data key>`` and answers with the kept samples on
  their own data key (attachment included). A transient-local subscription
  is a ``QueryingSubscriber``: its first query is ``*/<data key>``, then one
  query ``<zid>/<data key>`` for each transient-local publisher the graph
  cache discovers later; target ALL, consolidation NONE, replies on any key
  accepted, no timeout.
* **Advanced publisher and subscriber** (Jazzy 0.2.2 and later, Kilted
  0.6.x, Rolling 0.4.0 and later). Every publisher is a zenoh-ext
  ``AdvancedPublisher``; a transient-local one has ``publisher_detection``
  (a liveliness token ``<data key>/@adv/pub/<zid>/<eid>/_``) and a cache of
  ``depth`` samples whose queryable is that same key; RELIABLE +
  TRANSIENT_LOCAL adds sample-miss detection with a sporadic heartbeat every
  500 ms (Jazzy 0.2.4 and later, Kilted, Rolling 0.6.0 and later; from
  then on best-effort publishers are put BEST_EFFORT).
  A transient-local subscription is an ``AdvancedSubscriber`` with
  ``subscriber_detection``, history (``detect_late_publishers``,
  ``max_samples`` = its depth) and, when RELIABLE, recovery by heartbeat
  (the releases with the heartbeat):
  it queries ``<data key>/@adv/pub/**`` with ``_max=<depth>`` (and replies
  on any key), and the key of each publisher token that appears later. The
  cache answers the newest ``_max`` samples, oldest first, each with the
  publisher's source info (its entity id and a sequence number).
* The QoS is in the publisher's graph token (``wire.rmw_zenoh.parse_qos``):
  reliability 1/2, durability 1 = TRANSIENT_LOCAL, ``<history>,<depth>``;
  the release forms differ only in how the enum values are spelled, not in
  the values. zenoh-ros2-sdk 0.1.8 subscribers with a transient-local QoS
  query ``<data key>/@adv/pub/<zid>/**?_anyke;_max=<depth>`` once, for the
  publishers present when they start; its publishers keep nothing.

What this part does:

* **Subscribing.** A subscription asks history only of the publishers
  whose token says TRANSIENT_LOCAL: for each such token, when the
  subscription starts or when the token appears (again, after a reconnect),
  the current form is asked, ``<domain>/<topic>/*/*/@adv/pub/<zid>/**?_max=<depth>``,
  and when that brings nothing, the publication cache's,
  ``<zid>/<domain>/<topic>/*/*``; each reaches only that publisher's
  session (target ALL, consolidation NONE, replies on any key,
  :data:`HISTORY_TIMEOUT`). Each reply is a sample of the topic
  (``_zenoh_samples`` checks its key and attachment as any other); past the
  depths that session's transient-local publishers of the topic announce,
  replies are counted (``history_overflow``) and dropped.
* **No duplicates.** Once a topic has a transient-local publisher, every
  sample of its subscription, live or replayed, is checked against the
  highest sequence number delivered from its gid (the attachment's): one at
  or below it is skipped and counted in the subscription's
  ``stats.dropped_replay``. So a sample that arrives both live and from a
  cache, and history asked again after a reconnect, are delivered once, and
  a publisher's messages never arrive out of order. The record
  (:class:`LatchedMemory`) is the client's, not the connection's: a reconnect
  hands it to the new connection; it is forgotten when no local
  subscription wants the topic any more (a new subscription gets the history
  again). At most ``_zenoh_values.MAX_GIDS_PER_TOPIC`` publishers are remembered per
  topic, the oldest forgotten first.
* **Publishing latched.** ``advertise(topic, type, latch=True)`` declares
  an advanced publisher with a cache of ``queue_size`` samples (1 by
  default), publisher detection and, when reliable, the heartbeat, as the
  current releases do; its token says TRANSIENT_LOCAL with that depth. No
  publication cache is declared: the releases that query one (and Jazzy
  0.2.2 and 0.2.3, Rolling 0.4.0 and 0.5.0) read only the keyed attachment
  form, which this library does not write, so they drop our samples, live
  or kept, whatever answered them.

Limits: a sample lost on the way is not fetched again (rmw_zenoh's
reliable transient-local subscriptions recover a lost last sample from the
heartbeat; the link to the router is TCP, which loses none unless a
congested publisher drops); several local subscriptions to one topic share
one zenoh subscriber, so one that starts while another is already subscribed
does not get the history again; a publisher whose first sample arrives
before its token (whose samples were delivered before the topic had a
transient-local publisher) may be delivered once more from its cache; a
kept message older than one already delivered from the same publisher is never delivered."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final

from ..wire import rmw_zenoh as rz
from ._zenoh_node import ZenohNode
from ._zenoh_samples import ZenohSamples
from ._zenoh_values import Subscription

__all__ = ["HISTORY_TIMEOUT", "KEEP_ALL_LIMIT", "LatchedMemory", "ZenohLatched"]

KEEP_ALL_LIMIT: Final = 10_000
"""The most samples taken from a keep-all (depth 0) publisher's history."""
HISTORY_TIMEOUT: Final = 10.0
"""Seconds a history query waits for the caches' replies (they come at once;
the query ends when every cache it reached has answered)."""


class LatchedMemory:
    """The highest sequence number delivered per publisher gid, per topic of
    a transient-local publisher: one per client, carried across reconnects
    (see the module docstring)."""

    __slots__ = ("_topics",)

    def __init__(self) -> None:
        self._topics: dict[str, dict[bytes, int]] = {}

    def of(self, topic: str) -> dict[bytes, int]:
        """The record of ``topic`` (made empty the first time)."""
        return self._topics.setdefault(topic, {})

    def forget(self, topic: str) -> None:
        self._topics.pop(topic, None)


@dataclass(slots=True)
class _Asked:
    """One history query: for whom, the publisher session's zid, the most
    samples taken from it (the depths of that session's transient-local
    publishers of the topic), whether it is the publication cache's form
    (asked last), and the replies so far."""

    sub: Subscription
    zid: str
    limit: int
    cache_form: bool = False
    replies: int = 0


class ZenohLatched:
    """History for the subscriptions, caches for the latched publishers (see
    the module docstring). The adapter calls :meth:`watch` when a topic is
    subscribed, :meth:`forget` when it is not any more, :meth:`on_graph`
    after each graph change, and hands it each reply and query end first
    (:meth:`on_reply`, :meth:`on_done`: False when not one of its queries)."""

    def __init__(
        self,
        node: ZenohNode,
        samples: ZenohSamples,
        subscriptions: Mapping[str, Subscription],
        memory: LatchedMemory | None = None,
    ) -> None:
        """``memory``: the record of the connection this one replaces (a
        reconnect), else a new one."""
        self._node = node
        self._samples = samples
        self._subs = subscriptions
        self.memory = memory if memory is not None else LatchedMemory()
        self._asked: set[str] = set()  # publisher token keys whose history was asked
        self._queries: dict[int, _Asked] = {}  # history query id -> what it asks

    # -- subscribing -------------------------------------------------------------------------
    def watch(self, sub: Subscription) -> None:
        """``sub`` was subscribed: ask the topic's transient-local publishers."""
        for key, token in self._node.graph.tokens.items():
            if token.name == sub.topic:
                self._consider(key, token)

    def forget(self, topic: str) -> None:
        """No local subscription wants ``topic`` any more."""
        self.memory.forget(topic)
        graph = self._node.graph.tokens
        self._asked = {k for k in self._asked if k in graph and graph[k].name != topic}

    def on_graph(self) -> None:
        """Tokens came or went: ask each new transient-local publisher of a
        subscribed topic (one whose token went and came back is new)."""
        tokens = self._node.graph.tokens
        self._asked.intersection_update(tokens)
        for key, token in tokens.items():
            if key not in self._asked and token.name in self._subs:
                self._consider(key, token)

    def _consider(self, key: str, token: rz.Token) -> None:
        qos = token.qos
        if token.kind is not rz.EntityKind.PUBLISHER or qos is None or not qos.transient_local:
            return
        sub = self._subs.get(token.name or "")
        if sub is None or key in self._asked:
            return
        self._asked.add(key)
        if sub.seen is None:
            sub.seen = self.memory.of(sub.topic)
        data = self._node.data_selector(sub.topic)
        newest = f"?_max={qos.depth}" if qos.depth > 0 else ""  # 0: keep-all
        selector = f"{data}/@adv/pub/{token.zid}/**{newest}"
        query_id = self._node.session.query_history(selector, timeout=HISTORY_TIMEOUT)
        self._queries[query_id] = _Asked(sub, token.zid, self._kept_by(sub.topic, token.zid))

    def _kept_by(self, topic: str, zid: str) -> int:
        """The most samples the session ``zid`` keeps for ``topic``: the
        depths of its transient-local publishers of it (a keep-all one counts
        :data:`KEEP_ALL_LIMIT`)."""
        return sum(
            (t.qos.depth or KEEP_ALL_LIMIT)
            for t in self._node.graph.tokens.values()
            if t.kind is rz.EntityKind.PUBLISHER
            and t.name == topic
            and t.zid == zid
            and t.qos is not None
            and t.qos.transient_local
        )

    def on_reply(self, item: rz.Reply) -> bool:
        """A reply to a history query: the sample goes to its subscription
        (unless it was unsubscribed since). False for another query's."""
        asked = self._queries.get(item.query_id)
        if asked is None:
            return False
        sub = asked.sub
        if item.ok and item.key is not None and self._subs.get(sub.topic) is sub:
            asked.replies += 1
            if asked.replies > asked.limit:
                self._node.events.reject(
                    "history_overflow",
                    f"{sub.topic}: session {asked.zid} answered more samples than the"
                    f" {asked.limit} its transient-local publishers keep",
                )
                return True
            self._samples.on_kept(sub, item.key, item.payload, item.attachment)
        return True

    def on_done(self, query_id: int) -> bool:
        """A history query ended (False for another query's): when the
        current form brought nothing, the publication cache's is asked."""
        asked = self._queries.pop(query_id, None)
        if asked is None:
            return False
        sub = asked.sub
        if (
            asked.replies == 0
            and not asked.cache_form
            and self._subs.get(sub.topic) is sub
            and not self._node.session.closed
        ):
            selector = f"{asked.zid}/{self._node.data_selector(sub.topic)}"
            query_id = self._node.session.query_history(selector, timeout=HISTORY_TIMEOUT)
            self._queries[query_id] = _Asked(sub, asked.zid, asked.limit, cache_form=True)
        return True

    # -- publishing --------------------------------------------------------------------------
    def publisher(self, key: str, qos: rz.Qos) -> Any:
        """A publisher on ``key`` keeping its last ``qos.depth`` samples for
        late joiners, as the current releases' (see the module docstring);
        ``put`` and ``undeclare`` as a zenoh publisher's."""
        return self._node.session.declare_cached_publisher(
            key, depth=max(qos.depth, 1), reliable=qos.reliable
        )
