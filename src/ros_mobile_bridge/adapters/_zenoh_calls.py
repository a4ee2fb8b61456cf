"""The query engine of one Zenoh connection (:class:`ZenohQueries`): what
:class:`~._zenoh.ZenohAdapter` and its parts ask with zenoh ``get``\\ s.

A service call is a ``get`` on the service's exact key (its type's RIHS01
hash included) carrying rmw_zenoh's attachment (a sequence number, our
clock and this client's gid for that service, whose client (``SC``) token
is declared on the first call) and a deadline; the first reply is the
response. A liveliness query for our own node token is the round trip that
confirms delivery (zenoh keeps one session's order).

The adapter's reader hands each ``Reply`` and ``QueryDone`` item of the
inbox here (:meth:`ZenohQueries.on_reply`, :meth:`ZenohQueries.on_done`);
the pending calls, counted with the open action goals, are bounded by
``max_pending_requests``."""

from __future__ import annotations

import itertools
import time
from collections.abc import Callable, Sized
from typing import Any

import anyio

from .._errors import (
    ActionGoalError,
    DecodeError,
    RosBridgeError,
    SchemaError,
    ServiceError,
    ServiceTimeout,
    connection_lost,
)
from ..codec import CodecRegistry
from ..flow import PendingRequests
from ..wire import rmw_zenoh as rz
from ._shared import check_pending
from ._zenoh_node import ZenohNode
from ._zenoh_values import Query

__all__ = ["NoServerAnswered", "Replies", "ZenohQueries"]

Replies = list[tuple[bool, bytes, bytes | None]]
"""A query's replies: (ok, payload, attachment) each."""


class NoServerAnswered(ServiceError):
    """A query that ended early with no reply while the router is there: no
    queryable of the service was reached (the server left, or its
    declaration has not reached the router yet although its token has)."""


_ZENOH_TIMEOUT = "Timeout"
"""The error reply zenoh gives a query when its deadline passes."""
_DEADLINE_SHARE = 0.9
"""A query that ended with no reply after this share of its timeout timed
out (zenoh's timer and ours do not tick together)."""

_ROUTER_GRACE = 0.5
"""Seconds :meth:`ZenohQueries._router_gone` gives the session to see its
router's link close."""


async def _noop() -> None:
    return None


class ZenohQueries:
    """The queries of one connection: service calls, and the round trip
    (see the module docstring)."""

    def __init__(self, node: ZenohNode, goals: Sized) -> None:
        """``goals`` are the open action goals (the actions part's), counted
        with the pending calls against ``max_pending_requests``."""
        self._node = node
        self._session = node.session
        self._goals = goals
        self._client_gids: dict[str, tuple[bytes, int]] = {}  # service -> (gid, token)
        self._call_seq = itertools.count(1)
        self._queries: dict[int, Query] = {}
        self._calls: PendingRequests[Replies] = PendingRequests()

    def _client_identity(self, service: str, srv_type: str, hash_: str) -> bytes:
        known = self._client_gids.get(service)
        if known is not None:
            return known[0]
        key = self._node.entity_key(
            rz.EntityKind.CLIENT, name=service, type_name=srv_type, hash_=hash_, qos=rz.Qos()
        )
        gid = rz.entity_gid(key)
        self._client_gids[service] = (gid, self._session.declare_token(key))
        return gid

    def check_pending(self, what: str, *, goal: bool = False) -> None:
        """``ServiceError`` (``ActionGoalError`` for a ``goal``) naming
        ``what`` when ``max_pending_requests`` requests already wait."""
        waiting = len(self._calls) + len(self._goals)
        check_pending(self._node.options, waiting, what, ActionGoalError if goal else ServiceError)

    def start_query(
        self,
        service: str,
        srv_type: str,
        payload: bytes,
        timeout: float,
        on_done: Callable[[Replies], None] | None = None,
    ) -> int:
        """Send a call to ``service``; its replies go to ``on_done`` when
        the query ends (or to the caller of :meth:`request`)."""
        try:
            hash_ = self._node.type_hash(srv_type)
        except SchemaError as exc:
            raise ServiceError(service, f"cannot compute the type hash: {exc}") from exc
        key = rz.format_key(rz.TopicKey(self._node.domain, service, srv_type, hash_))
        gid = self._client_identity(service, srv_type, hash_)
        attachment = rz.encode_attachment(next(self._call_seq), time.time_ns(), gid)
        query_id = self._session.query(key, payload=payload, attachment=attachment, timeout=timeout)
        self._queries[query_id] = Query(service, on_done=on_done)
        return query_id

    async def request(self, service: str, srv_type: str, request: Any, timeout: float) -> Any:
        """Call ``service`` (of type ``srv_type``) and return the decoded
        response; ``ServiceError`` with the reason otherwise:
        ``ServiceTimeout`` when no reply came within ``timeout``,
        ``NotConnected`` (the connection was lost) when the query ended
        early because the router went away, a ``ServiceError`` saying no
        server answered when it ended early for another reason (the server
        left)."""
        codecs = self._node.codecs
        req_name, res_name = CodecRegistry.service_type_names(srv_type)
        try:
            payload = codecs.encoder(req_name, "cdr")(request if request is not None else {})
            decode = codecs.decoder(res_name, "cdr")
        except SchemaError as exc:
            raise ServiceError(service, f"no definition of {srv_type}: {exc}") from exc
        self.check_pending(service)
        query_id = self.start_query(service, srv_type, payload, timeout)
        started = anyio.current_time()
        replies = await self._calls.request(query_id, _noop)
        for ok, body, _attachment in replies:
            if not ok:
                text = body.decode("utf-8", "replace")
                if text == _ZENOH_TIMEOUT:
                    break  # zenoh's own word for the query's deadline
                raise ServiceError(service, f"the server replied with an error: {text}")
            try:
                return decode(memoryview(body))
            except DecodeError as exc:
                raise ServiceError(service, f"the response does not decode: {exc}") from exc
        elapsed = anyio.current_time() - started
        if elapsed >= timeout * _DEADLINE_SHARE:
            raise ServiceTimeout(service, timeout)
        # the query ended early with no reply: its route is gone
        if await self._router_gone():
            raise connection_lost(f"zenoh: the router went away during the call to {service}")
        raise NoServerAnswered(
            service, f"no server answered (the query ended after {elapsed:.2g} s with no reply)"
        )

    async def _router_gone(self) -> bool:
        """Whether the session lost its router: asked when a query ended
        early with no reply. The session may learn that its link closed a
        moment after the query ended: asked again for up to
        :data:`_ROUTER_GRACE` seconds."""
        deadline = anyio.current_time() + _ROUTER_GRACE
        while True:
            if self._node.lost is not None or self._session.closed:
                return True
            if not await anyio.to_thread.run_sync(self._session.routers):
                return True
            if anyio.current_time() >= deadline:
                return False
            await anyio.sleep(_ROUTER_GRACE / 10)

    async def round_trip(self, timeout: float) -> bool:
        """A liveliness query for our own node token, answered by the router:
        everything put before it has left this session (zenoh keeps one
        session's order). True when the answer came within ``timeout``."""
        self._node.check_alive()
        query_id = self._session.query_liveliness(self._node.node_key, timeout=timeout)
        finished = anyio.Event()
        self._queries[query_id] = Query("round trip", on_done=lambda _r: finished.set())
        with anyio.move_on_after(timeout):
            await finished.wait()
        return finished.is_set()

    # -- from the reader ------------------------------------------------------------------
    def on_reply(self, item: rz.Reply) -> None:
        """One reply to a query of ours (kept until the query ends)."""
        query = self._queries.get(item.query_id)
        if query is not None:
            query.replies.append((item.ok, item.payload, item.attachment))

    def on_done(self, query_id: int) -> None:
        """The query ``query_id`` ended: its replies to whoever waits."""
        query = self._queries.pop(query_id, None)
        if query is None:
            return
        if query.on_done is not None:
            query.on_done(query.replies)
        else:
            self._calls.resolve(query_id, query.replies)

    def fail_all(self, error: RosBridgeError) -> None:
        """Fail every call waiting for its replies with ``error``."""
        self._calls.fail_all(error)
