"""Serving a service over Zenoh, as rmw_zenoh_cpp's service servers do
(:class:`ZenohServing`, the serving part of :class:`~._zenoh.ZenohAdapter`).

A served service is a *complete* queryable on the service's data key (its
type's RIHS01 hash included) and a service-server (``SS``) liveliness token
with the services' default QoS, so ROS tools and other rmw_zenoh nodes see
it. Each query is one call: its CDR payload decoded with the request type,
its attachment (sequence number, timestamp, the caller's gid) kept until the
answer. The answer is one reply on the service key carrying the response's
CDR and an attachment with the *request's* sequence number, the *caller's*
gid and this client's clock, by which the caller matches it to its call. A
``result: false`` answer is a zenoh error reply carrying the reason (an
rmw_zenoh_cpp caller logs it and keeps waiting until its own timeout; a
caller of this library gets a ``ServiceError`` with the reason at once).

A call that cannot be handled (no valid attachment, a payload that does not
decode, a service no longer served) is answered with an error reply, logged
and counted as rejected; the reader goes on. The session bounds the calls
waiting for an answer (``ZenohSession.max_open_queries``); calls past that
are answered with an error by the session and counted here. Unadvertising a
service (or closing) answers its open calls with an error."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import anyio

from .._errors import ConnectError, DecodeError, SchemaError, ServiceError
from ..codec import CodecRegistry
from ..flow import Decoder
from ..interfaces._base import RosMessage
from ..wire import rmw_zenoh as rz
from ..wire._limits import truncate_for_log
from ._seam import ServiceHandler
from ._zenoh_calls import ZenohQueries
from ._zenoh_node import ZenohNode

__all__ = ["ZenohServing"]


@dataclass(slots=True)
class _Served:
    """One service this client serves over Zenoh."""

    name: str
    type: str
    handler: ServiceHandler
    key: str
    tag: int
    decode: Decoder
    encode: Any
    queryable: int  # session handles
    token: int


@dataclass(slots=True)
class _Open:
    """A call waiting for its answer: the service and its attachment."""

    service: str
    attachment: rz.Attachment


class ZenohServing:
    """``advertise_service`` / ``unadvertise_service`` / ``respond_service``
    over zenoh queryables (a :class:`~._seam.ServiceHost`). The adapter's
    reader hands each ``Request`` item of the inbox to :meth:`on_request`
    and, after each batch, calls :meth:`count_refused_queries`."""

    def __init__(self, node: ZenohNode, queries: ZenohQueries) -> None:
        """``queries`` confirms an advertisement with its round trip."""
        self._node = node
        self._session = node.session
        self._options = node.options
        self._log = node.log
        self._codecs = node.codecs
        self._events = node.events
        self._queries = queries
        self._served: dict[str, _Served] = {}
        self._served_by_tag: dict[int, _Served] = {}
        self._open_calls: dict[str, _Open] = {}  # request id -> the call
        self._refused_seen = 0  # the session's refused_queries already counted

    async def advertise_service(
        self, name: str, service_type: str, handler: ServiceHandler, *, confirm: bool = True
    ) -> None:
        """Serve ``name``: the queryable and its ``SS`` token. ``SchemaError``
        when the type's definition (or a nested one) is unknown, so its hash
        and codecs cannot be built; with ``confirm``, returns once the
        declarations reached the router (a round trip)."""
        if name in self._served:
            raise ValueError(f"{name} is served by this client already")
        self._node.check_alive()
        req_name, res_name = CodecRegistry.service_type_names(service_type)

        def build() -> tuple[str, Decoder, Any]:  # generating codecs can take a while
            return (
                self._node.type_hash(service_type),
                self._codecs.decoder(req_name, "cdr"),
                self._codecs.encoder(res_name, "cdr"),
            )

        try:
            hash_, decode, encode = await anyio.to_thread.run_sync(build)
        except SchemaError as exc:
            raise SchemaError(f"cannot serve {name} as {service_type}: {exc}") from exc
        if name in self._served:  # served meanwhile, by a concurrent call
            raise ValueError(f"{name} is served by this client already")
        key = rz.format_key(rz.TopicKey(self._node.domain, name, service_type, hash_))
        token_key = self._node.entity_key(
            rz.EntityKind.SERVICE,
            name=name,
            type_name=service_type,
            hash_=hash_,
            qos=rz.Qos(),  # the services' default: reliable, volatile, keep last 10
        )
        tag = self._node.new_tag()
        queryable = self._session.declare_queryable(key, tag)
        token = self._session.declare_token(token_key)
        served = _Served(name, service_type, handler, key, tag, decode, encode, queryable, token)
        self._served[name] = served
        self._served_by_tag[tag] = served
        if confirm and not await self._queries.round_trip(self._options.service_timeout):
            raise ServiceError(name, "the router did not confirm serving it in time")

    async def unadvertise_service(self, name: str) -> None:
        """Stop serving ``name``: the token and the queryable go; the calls
        still open are answered with an error (a no-op when not served)."""
        served = self._served.pop(name, None)
        if served is None:
            return
        self._served_by_tag.pop(served.tag, None)
        for request_id in [r for r, call in self._open_calls.items() if call.service == name]:
            del self._open_calls[request_id]
        self._session.undeclare(served.token)
        self._session.undeclare(served.queryable)  # answers its open queries

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        """Answer the call ``request_id``: the response's CDR with the
        rmw_zenoh attachment (``result``), or an error reply with
        ``str(values)``. ``DecodeError`` (nothing sent, the call still open)
        when ``values`` does not fit the response type; ``ConnectError``
        when the session is gone. A call no longer open (answered, or ended
        by an unadvertise) is ignored."""
        call = self._open_calls.get(request_id)
        served = self._served.get(name)
        if call is None or served is None or call.service != name:
            return
        if self._session.closed:
            raise ConnectError("zenoh: the session is closed")
        query_id = int(request_id)
        if not result:
            del self._open_calls[request_id]
            self._session.reply_error(query_id, str(values))
            return
        payload = bytes(served.encode(values))  # DecodeError naming the field: still open
        attachment = rz.encode_attachment(
            call.attachment.sequence, time.time_ns(), call.attachment.gid
        )
        del self._open_calls[request_id]
        try:
            self._session.reply(query_id, served.key, payload, attachment)
        except Exception as exc:  # zenoh refused it (a closing session)
            raise ConnectError(f"zenoh: the reply to {name} failed: {exc}") from exc

    # -- from the reader ------------------------------------------------------------------
    async def on_request(self, item: rz.Request) -> None:
        """One call to a served service: decoded and handed to its handler,
        or answered with an error (logged, counted) when it cannot be."""
        served = self._served_by_tag.get(item.tag)
        if served is None:  # unadvertised while the call was on its way
            self._session.reply_error(item.query_id, "this client does not serve it")
            return
        name = served.name
        try:
            attachment = rz.decode_attachment(item.attachment)
        except rz.MalformedAttachment as exc:
            self._refuse(item, name, "attachment", f"no valid rmw_zenoh attachment: {exc}")
            return
        try:
            args = served.decode(memoryview(item.payload))
        except DecodeError as exc:
            self._refuse(item, name, "decode", f"the request does not decode: {exc}")
            return
        if not isinstance(args, RosMessage):  # a CDR decoder gives an instance
            self._refuse(item, name, "decode", "the request is not a message")
            return
        request_id = str(item.query_id)
        self._open_calls[request_id] = _Open(name, attachment)
        await served.handler.on_service_request(self, request_id, args)

    def _refuse(self, item: rz.Request, name: str, reason: str, text: str) -> None:
        self._session.reply_error(item.query_id, text)
        self._log.warning("%s: a call was refused: %s", name, truncate_for_log(text))
        self._events.reject(reason, f"{name}: {text}")

    def count_refused_queries(self) -> None:
        """Count the calls the session refused past its open-query bound."""
        refused = self._session.refused_queries
        if refused != self._refused_seen:
            new = refused - self._refused_seen
            self._refused_seen = refused
            self._events.reject(
                "service_limit",
                f"{new} calls to served services were refused: "
                f"{self._session.max_open_queries} already waited for an answer",
                new,
            )

    def close(self) -> None:
        """The session closes: forget every served service and open call
        (closing the session undeclares them and answers the calls)."""
        self._served.clear()
        self._served_by_tag.clear()
        self._open_calls.clear()
