"""What the parts of one Zenoh connection share (:class:`ZenohNode`): the
session, the options, the domain and codecs, this client's ROS node (its
name, its ids, the keys of the tokens that make it visible to ROS tools),
the inbox tags and the table that routes a tagged sample to its
subscription, the graph, and the :class:`~._shared.EventSource`.

:class:`~._zenoh.ZenohAdapter` builds one and gives it to each part it
holds (queries, actions, parameters, serving, type descriptions, samples);
every part reads it and none reads another's state."""

from __future__ import annotations

import itertools
import logging
from typing import Any

from .._errors import ConnectError
from .._options import ClientOptions
from ..codec import CodecRegistry, type_hash
from ..transport._zenoh import ZenohSession
from ..wire import rmw_zenoh as rz
from ._shared import EventSource
from ._zenoh_graph import ZenohGraph
from ._zenoh_values import Subscription

__all__ = ["ZenohNode"]


class ZenohNode:
    """One zenoh session as a ROS node (see the module docstring)."""

    def __init__(
        self,
        session: ZenohSession,
        options: ClientOptions,
        domain: int,
        codecs: CodecRegistry,
        events: EventSource,
    ) -> None:
        self.session = session
        self.options = options
        self.log: logging.Logger = options.logger
        self.domain = domain
        self.codecs = codecs
        self.events = events
        self.routes: dict[int, Subscription] = {}
        """Inbox tag -> the subscription its samples are for (the user's
        topics, the actions' feedback, ``/parameter_events``)."""
        self.lost: str | None = None
        """Why the session was lost (set by the reader), else None."""
        self._ids = itertools.count(0)  # node and entity ids, as rmw_zenoh counts them
        self._tags = itertools.count(1)  # inbox tags (0 is the graph)
        self.node_id = next(self._ids)
        self.node_name = f"rmb_{session.zid[:12]}"
        self.node_key = self.token_key(rz.EntityKind.NODE, self.node_id)
        """Our node's liveliness token (``NN``)."""
        self.graph = ZenohGraph(domain, options.max_channels, events, self.node_key)

    def new_tag(self) -> int:
        """A fresh inbox tag (for a subscriber or a queryable)."""
        return next(self._tags)

    def token_key(self, kind: rz.EntityKind, entity_id: int, **kw: Any) -> str:
        """The liveliness token of our node's entity ``entity_id``
        (``name``, ``type_name``, ``hash_``, ``qos`` as :class:`rz.Token`
        takes them)."""
        return rz.format_token(self._token(kind, entity_id, **kw))

    def entity_key(self, kind: rz.EntityKind, **kw: Any) -> str:
        """:meth:`token_key` of a new entity of our node (the next id)."""
        return self.token_key(kind, next(self._ids), **kw)

    def _token(
        self,
        kind: rz.EntityKind,
        entity_id: int,
        name: str | None = None,
        type_name: str | None = None,
        hash_: str | None = None,
        qos: rz.Qos | None = None,
    ) -> rz.Token:
        return rz.Token(
            domain=self.domain,
            zid=self.session.zid,
            node_id=self.node_id,
            entity_id=entity_id,
            kind=kind,
            enclave="",
            namespace="/",
            node_name=self.node_name,
            name=name,
            type_name=type_name,
            type_hash=hash_,
            qos=qos,
        )

    def type_hash(self, type_name: str) -> str:
        """The RIHS01 hash of ``type_name``; ``SchemaError`` when a nested
        definition is missing (a wrong hash would reach nobody, silently)."""
        return type_hash(self.codecs, type_name)

    def key(self, name: str, type_name: str) -> str:
        """The exact data key of ``name`` with type ``type_name`` (its hash
        included); ``SchemaError`` as :meth:`type_hash`."""
        return rz.format_key(rz.TopicKey(self.domain, name, type_name, self.type_hash(type_name)))

    def data_selector(self, topic: str) -> str:
        """The key expression of every sample of ``topic`` (any type and hash)."""
        return f"{self.domain}/{topic.lstrip('/')}/*/*"

    def check_alive(self) -> None:
        """``ConnectError`` when the session is lost or closed."""
        if self.lost is not None or self.session.closed:
            raise ConnectError(f"zenoh: {self.lost or 'the session is closed'}")
