"""Serving a service over rosbridge (``advertise_service``): the record of
each service this connection serves, the bridge's refusals of them and its
complaints about the answers sent to their callers. The serving part
of :class:`~._rosbridge.RosbridgeAdapter`."""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass
from typing import Any, Final

import anyio

from .._errors import DecodeError, RosBridgeError, SchemaError, ServiceError
from ..codec import CodecRegistry, same_type_name
from ..transport import WebSocket
from ..wire import rosbridge as rb
from ..wire._limits import truncate_for_log
from ._rosbridge_calls import _INTERNAL_TIMEOUT, RosbridgeCalls
from ._seam import ServiceHandler
from ._shared import as_instance


def _refusal(name: str, service_type: str, text: str) -> RosBridgeError:
    """The error for the bridge's refusal to serve ``name``."""
    if "another client" in text:
        return ServiceError(name, f"the bridge refused to serve it: {text}")
    return SchemaError(f"the bridge refused to serve {name} as {service_type}: {text}")


@dataclass(slots=True)
class _Served:
    """A service this connection serves (``advertise_service``)."""

    type: str
    handler: ServiceHandler
    id: str
    error: str | None = None
    confirmed: bool = False  # nobody waits for the answer: a refusal goes to the handler


_FAILED_ANSWERS_KEPT: Final = 256


class RosbridgeServing:
    """The services a rosbridge connection serves (``Adapter.serving``):
    advertising them (and confirming that through the graph), handing each
    call the reader reads to its handler (:meth:`on_request`), answering the
    callers, and the bridge's error statuses about either
    (:meth:`on_status`)."""

    def __init__(
        self,
        ws: WebSocket,
        engine: rb.RosbridgeEngine,
        calls: RosbridgeCalls,
        codecs: CodecRegistry,
        log: logging.Logger,
    ) -> None:
        self._ws = ws
        self._engine = engine
        self._calls = calls
        self._codecs = codecs
        self._log = log
        self._served: dict[str, _Served] = {}
        self._failed_answers: dict[str, str] = {}  # request id -> service, answered false

    async def advertise_service(
        self, name: str, service_type: str, handler: ServiceHandler, *, confirm: bool = True
    ) -> None:
        if name in self._served:
            raise ValueError(f"{name} is served by this client already")
        served = _Served(service_type, handler, self._calls.next_id(f"advertise_service:{name}"))
        self._served[name] = served
        sent = False
        try:
            await self._ws.send(self._engine.advertise_service(name, service_type, id=served.id))
            sent = True
            if not confirm:
                served.confirmed = True  # a refusal goes to handler.on_service_failed
                return
            await self._confirm_served(name, served)
            if served.error is not None:
                raise _refusal(name, service_type, served.error)
            served.confirmed = True
        except BaseException:
            # never sent, or refused (the name may be another client's): free
            if not (sent and served.error is None) and self._served.get(name) is served:
                del self._served[name]
            # else not confirmed (a timeout, a cancellation) but maybe served:
            # the entry stays, so calls still reach the handler, until the
            # caller answers what came and calls unadvertise_service
            raise

    async def _confirm_served(self, name: str, served: _Served) -> None:
        """Wait until the bridge refused ``name`` (``served.error``) or the
        graph shows it served with its type. rosbridge_server_rs may report
        a refusal after answering requests sent later, so a round trip is no
        proof; the graph is. ``ServiceError`` when neither came within the
        adapter's own deadline."""
        with anyio.move_on_after(_INTERNAL_TIMEOUT):
            while served.error is None:
                try:
                    answer = await self._calls.rosapi("/rosapi/service_type", {"service": name})
                except ServiceError:
                    answer = None
                found = answer.get("type") if isinstance(answer, dict) else None
                if served.error is None and isinstance(found, str) and found:
                    if same_type_name(found, served.type):
                        return
                    served.error = f"the graph has {name} as {found}"
                    return
                await anyio.sleep(0.05)
            return
        raise ServiceError(
            name, f"the bridge did not confirm serving it in {_INTERNAL_TIMEOUT:g} s"
        )

    async def on_request(self, event: rb.ServiceRequest) -> None:
        """A call the reader read: to the service's handler, or answered
        ``result: false`` at once when this connection does not serve it
        (never left waiting)."""
        served = self._served.get(event.service)
        if served is None:
            await self.respond_service(
                event.service, event.id, "this client does not serve it", False
            )
        else:
            request_type = CodecRegistry.service_type_names(served.type)[0]
            try:
                args = as_instance(self._codecs, request_type, event.args)
            except DecodeError as exc:
                await self.respond_service(
                    event.service, event.id, f"the request does not decode: {exc}", False
                )
                return
            await served.handler.on_service_request(self, event.id, args)

    async def unadvertise_service(self, name: str) -> None:
        served = self._served.pop(name, None)
        if served is not None and not self._ws.closed:
            await self._ws.send(self._engine.unadvertise_service(name, id=served.id))
            await self._calls.round_trip()  # served no more once this returns

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        if result:
            served = self._served.get(name)
            body: str | bytes
            if served is not None:
                response = CodecRegistry.service_type_names(served.type)[1]
                if self._codecs.has_schema(response):
                    self._codecs.encoder(response, "cdr")(values)  # DecodeError naming the field
                body = self._codecs.encoder(response, "json")(values)
            else:
                body = json.dumps(values)
        else:
            body = json.dumps(str(values))
            if len(self._failed_answers) >= _FAILED_ANSWERS_KEPT:
                del self._failed_answers[next(iter(self._failed_answers))]
            self._failed_answers[request_id] = name
        await self._ws.send(self._engine.service_response(name, body, id=request_id, result=result))

    def on_status(self, event: rb.Status) -> bool:
        """Handle an error status about a served service (the bridge refused
        to serve it) or about an answer sent to one of its callers; True when
        it was one of those."""
        key = event.id or ""
        error = event.level == "error"
        for name, served in self._served.items():
            if served.id == key and error:
                served.error = event.msg
                self._log.error("the bridge refused to serve %s: %s", name, event.msg)
                if served.confirmed:  # nobody waits for it: end that serve() block
                    del self._served[name]  # refused: not ours to unadvertise
                    served.handler.on_service_failed(_refusal(name, served.type, event.msg))
                return True
        if error and key.startswith("service_request:"):
            service = self._failed_answers.pop(key, None)
            if service is not None:
                # rosbridge_server_rs: "ROS services cannot carry an error
                # response; request will time out"
                self._log.info(
                    "%s: answered %s with result false; the bridge says: %s",
                    service,
                    key,
                    truncate_for_log(event.msg),
                )
            else:
                self._log.warning(
                    "the bridge refused the answer to %s: %s", key, truncate_for_log(event.msg)
                )
            return True
        return False
