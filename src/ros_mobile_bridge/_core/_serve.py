"""Serving a service: the objects :meth:`Client.serve` hands out.

The adapter's reader hands each forwarded call to :class:`Serving`
(``on_service_request``), the engine of one ``serve()`` block, which queues
it (bounded) for the consumer's ``async for`` over :class:`ServiceRequests`,
its face. Every request is answered exactly once: by the consumer
(:meth:`ServiceRequest.reply` / :meth:`ServiceRequest.fail`), or with
``result: false`` and a reason when the queue is full, when its deadline
passes, when the consumer moves on to the next request without answering, or
when the ``serve()`` block ends. A request is never left waiting on the
server's side because of this client."""

from __future__ import annotations

import logging
import math
from collections import deque
from collections.abc import AsyncIterator, Awaitable, Callable, Mapping
from contextlib import asynccontextmanager
from dataclasses import dataclass
from typing import Any, Final, Generic, Literal

import anyio

from .._errors import (
    ConnectError,
    MessageError,
    NotConnected,
    NotSupportedError,
    RosBridgeError,
    ServiceError,
)
from .._types import RequestT, ResponseT
from ..adapters import ServiceHost
from ..interfaces._base import RosMessage

__all__ = ["ServeStats", "ServedServices", "ServiceRequest", "ServiceRequests", "Serving"]

DEFAULT_SERVE_TIMEOUT: Final = 10.0
DEFAULT_SERVE_BUFFER: Final = 16

Outcome = Literal["replied", "failed", "unanswered", "overflowed", "lost"]


@dataclass(frozen=True, slots=True)
class ServeStats:
    """Counters of one ``serve()`` block (a snapshot).

    ``received``: calls that arrived. Each ends in exactly one of:
    ``replied`` (:meth:`ServiceRequest.reply`), ``failed``
    (:meth:`ServiceRequest.fail`), ``unanswered`` (answered ``result: false``
    by the library: its deadline passed, the consumer moved on, or the block
    ended), ``overflowed`` (answered ``result: false`` on arrival: ``buffer``
    unread requests were already queued), ``lost`` (the connection that
    carried it went away before it was answered; the bridge dropped it).
    ``pending`` are the ones not answered yet."""

    received: int = 0
    replied: int = 0
    failed: int = 0
    unanswered: int = 0
    overflowed: int = 0
    lost: int = 0

    @property
    def pending(self) -> int:
        return self.received - (
            self.replied + self.failed + self.unanswered + self.overflowed + self.lost
        )


class _Call:
    """One forwarded call, as the engine (:class:`Serving`) tracks it: the
    connection that carried it, the server's id, the deadline, how it was
    answered (None while open) and the user's face, :attr:`request`."""

    __slots__ = ("deadline", "host", "id", "outcome", "request")

    def __init__(
        self,
        host: ServiceHost,
        request_id: str,
        args: dict[str, Any],
        deadline: float,
        service: str,
        answer: Answer,
    ) -> None:
        self.host = host
        self.id = request_id
        self.deadline = deadline
        self.outcome: Outcome | None = None
        self.request = ServiceRequest(self, service, args, answer)


Answer = Callable[[_Call, Outcome, Any, bool], Awaitable[None]]
"""The engine's answering step: (call, outcome, values, result)."""


class ServiceRequest(Generic[RequestT, ResponseT]):
    """One call to a service this client serves. ``args`` is the decoded
    request: an instance of the service's ``Request`` class when the
    library knows the type's definition (``req.args.a``), else a dict;
    ``id`` the server's id for the call, ``service`` the service name,
    ``deadline`` the ``anyio.current_time()`` after which the library
    answers it ``result: false``. Served as ``serve(name, AddTwoInts)``, a
    request is a ``ServiceRequest[AddTwoInts.Request, AddTwoInts.Response]``
    for type checkers.

    Answer it once, with :meth:`reply` or :meth:`fail`."""

    __slots__ = ("_answer", "_call", "args", "deadline", "id", "service")

    args: RequestT

    def __init__(self, call: _Call, service: str, args: Any, answer: Answer) -> None:
        self._call = call
        self._answer = answer
        self.id = call.id
        self.service = service
        self.args = args
        self.deadline = call.deadline

    def __repr__(self) -> str:
        return f"ServiceRequest({self.service!r}, id={self.id!r}, args={self.args!r})"

    @property
    def answered(self) -> bool:
        """Whether this request has been answered (by anyone)."""
        return self._call.outcome is not None

    @property
    def outcome(self) -> Outcome | None:
        """How it was answered (a :class:`ServeStats` counter name), or None."""
        return self._call.outcome

    async def reply(self, values: ResponseT | Mapping[str, Any] | None = None) -> None:
        """Answer with the response ``values``: an instance of the
        service's ``Response`` class (``AddTwoInts.Response(sum=3)``) or a
        dict (missing fields are zero when the type is known). Raises
        ``TypeError`` for a value that is neither, :class:`~ros_mobile_bridge.MessageError` (a
        ``ValueError``) naming the field when it does not fit the response
        type (the request stays unanswered then), ``ServiceError`` when the
        request was answered already (by the library at its deadline, for
        instance) and ``NotConnected`` when the connection that carried it
        is gone (the caller gets no answer). Cancelled before the answer was
        written, the request stays open (the library answers it
        ``result: false`` at its deadline or when the block ends); once
        written, it counts as replied even if a cancellation lands next."""
        if values is None:
            values = {}
        if isinstance(values, RosMessage):
            await self._answer(self._call, "replied", values, True)
            return
        if not isinstance(values, Mapping):
            raise TypeError(
                f"values must be a message instance or a mapping (dict), not {type(values).__name__}"
            )
        await self._answer(self._call, "replied", dict(values), True)

    async def fail(self, message: str = "the service failed") -> None:
        """Answer with ``result: false`` and ``message``. The rosbridge
        protocol carries it; a ROS 2 service cannot: a ROS caller behind
        rosbridge_server_rs gets no answer and fails at its own timeout (see
        docs/serving.md). Raises like :meth:`reply`."""
        if not isinstance(message, str):
            raise TypeError(f"message must be a str, not {type(message).__name__}")
        await self._answer(self._call, "failed", message, False)


class ServiceRequests(Generic[RequestT, ResponseT]):
    """The requests to one served service, in arrival order: ``async for req
    in requests``. Yielded by :meth:`Client.serve`; generic in the
    service's ``Request`` and ``Response`` classes when it names the
    service's class.

    Moving on to the next request answers the previous one ``result: false``
    if the loop body did not. The iteration raises ``NotConnected`` when the
    connection is lost for good, and ends when the ``serve()`` block ends."""

    def __init__(self, serving: Serving) -> None:
        self._serving = serving
        self.name = serving.name
        self.service_type = serving.service_type
        self.timeout = serving.timeout
        self.buffer = serving.buffer

    @property
    def stats(self) -> ServeStats:
        """The counters so far (see :class:`ServeStats`)."""
        return self._serving.stats

    def __aiter__(self) -> ServiceRequests[RequestT, ResponseT]:
        return self

    async def __anext__(self) -> ServiceRequest[RequestT, ResponseT]:
        request: ServiceRequest[RequestT, ResponseT] = await self._serving.next()
        return request


class Serving:
    """The engine behind one ``serve()`` block: the adapter's
    :class:`~ros_mobile_bridge.adapters.ServiceHandler` for the service, the
    bounded queue the consumer reads (through :attr:`requests`, the face
    :meth:`Client.serve` yields), the deadlines and the answers."""

    def __init__(
        self,
        name: str,
        service_type: str,
        *,
        timeout: float,
        buffer: int,
        current: Callable[[], ServiceHost | None],
        teardown_timeout: float,
        logger: logging.Logger,
    ) -> None:
        self.name = name
        self.service_type = service_type
        self.timeout = timeout
        self.buffer = buffer
        self._current = current
        self._teardown_timeout = teardown_timeout
        self._log = logger
        self._queue: deque[_Call] = deque()  # not read yet (some answered)
        # every request received and not counted yet, in arrival order: the
        # deadline and the block's end answer these, wherever they are
        self._unsettled: dict[_Call, None] = {}
        self._taken: _Call | None = None
        self._wake = anyio.Event()
        self._changed = anyio.Event()
        self._closed = False
        self._error: RosBridgeError | None = None
        self._counts: dict[str, int] = dict.fromkeys(
            ("received", "replied", "failed", "unanswered", "overflowed", "lost"), 0
        )
        self.requests = ServiceRequests(self)

    @property
    def stats(self) -> ServeStats:
        """The counters so far (see :class:`ServeStats`)."""
        return ServeStats(**self._counts)

    # -- from the adapter's reader ------------------------------------------------
    async def on_service_request(self, host: ServiceHost, request_id: str, args: Any) -> None:
        """Queue a forwarded call; answer ``result: false`` at once when
        serving ended or ``buffer`` requests already wait."""
        self._counts["received"] += 1
        if self._closed:
            self._counts["unanswered"] += 1
            await host.respond_service(self.name, request_id, "the service is shutting down", False)
            return
        if len(self._queue) >= self.buffer:  # drop the ones answered while queued
            self._queue = deque(c for c in self._queue if c.outcome is None)
        if len(self._queue) >= self.buffer:
            self._counts["overflowed"] += 1
            self._log.warning(
                "%s: %d requests already wait to be read; a call was refused",
                self.name,
                self.buffer,
            )
            await host.respond_service(
                self.name,
                request_id,
                f"the service is busy: {self.buffer} requests already wait",
                False,
            )
            return
        deadline = anyio.current_time() + self.timeout
        call = _Call(host, request_id, args, deadline, self.name, self.answer)
        self._queue.append(call)
        self._unsettled[call] = None
        self._wake.set()
        self._changed.set()

    def on_service_failed(self, error: RosBridgeError) -> None:
        """The adapter's word that the bridge refused the service after it
        was advertised (a refusal arriving after confirmation, or after a
        restore that could not wait for one): the iteration raises it."""
        self._log.error("%s is not served: %s", self.name, error)
        self.fail(error)

    # -- the consumer --------------------------------------------------------------
    async def next(self) -> ServiceRequest:
        """The next request for the consumer (``ServiceRequests.__anext__``),
        answering the one handed out before if the loop body did not."""
        previous, self._taken = self._taken, None
        if previous is not None and previous.outcome is None:
            await self._auto_fail(previous, "the handler moved on without answering")
        while True:
            while self._queue:
                call = self._queue.popleft()
                if call.outcome is not None:
                    # expired while queued (or being answered now: if that
                    # answer is cancelled unsent, the deadline or the block's
                    # end answers it, never the consumer)
                    continue
                if call.host is not self._current():
                    self._settle(call, "lost")
                    continue
                self._taken = call
                return call.request
            if self._error is not None:
                raise self._error
            if self._closed:
                raise StopAsyncIteration
            self._wake = anyio.Event()
            await self._wake.wait()

    # -- answering -----------------------------------------------------------------
    def _settle(self, call: _Call, outcome: Outcome) -> None:
        call.outcome = outcome
        self._counts[outcome] += 1
        self._unsettled.pop(call, None)
        self._changed.set()

    def _unclaim(self, call: _Call) -> None:
        """An answer was not sent (cancelled before the write): the request
        is open again, for the deadline or the block's end to answer."""
        call.outcome = None
        self._changed.set()  # the deadline task may have left it out

    async def answer(self, call: _Call, outcome: Outcome, values: Any, result: bool) -> None:
        """The consumer's answer (:meth:`ServiceRequest.reply` /
        :meth:`ServiceRequest.fail`), raising as those document."""
        if call.outcome is not None:
            raise ServiceError(
                self.name, f"request {call.id} was answered already ({call.outcome})"
            )
        host = call.host
        if host is not self._current():
            self._settle(call, "lost")
            raise NotConnected(
                f"the connection that carried request {call.id} to {self.name} is gone;"
                " the caller got no answer"
            )
        call.outcome = outcome  # claimed: the deadline cannot answer it too
        # respond_service writes the frame as its last step (the write itself
        # shielded): when it raises, nothing was sent; once it returns, the
        # answer is out, whatever cancellation lands next
        try:
            await host.respond_service(self.name, call.id, values, result)
        except MessageError as exc:
            self._unclaim(call)  # still the caller's to answer
            raise exc.in_call(f"reply to {self.name}") from exc
        except ConnectError as exc:
            self._settle(call, "lost")
            raise NotConnected(
                f"disconnected: {exc} (the answer to {call.id} was not sent)"
            ) from exc
        except BaseException:
            # cancelled before the write: the connection is fine and the
            # request still open; the deadline or the block's end answers it
            self._unclaim(call)
            raise
        self._settle(call, outcome)

    async def _auto_fail(self, call: _Call, reason: str) -> None:
        """Answer ``result: false`` with ``reason`` on the consumer's behalf
        (never raises; a lost connection counts the request as lost)."""
        if call.outcome is not None:
            return
        host = call.host
        if host is not self._current():
            self._settle(call, "lost")
            return
        self._log.info("%s: request %s answered result false: %s", self.name, call.id, reason)
        call.outcome = "unanswered"  # claimed, as in answer
        try:
            await host.respond_service(self.name, call.id, reason, False)
        except RosBridgeError as exc:
            self._settle(call, "lost")
            self._log.debug("%s: could not answer %s: %s", self.name, call.id, exc)
            return
        except BaseException:
            # cancelled before the write: open again, so the deadline or
            # close answers it (a claim left behind would make them skip it)
            self._unclaim(call)
            raise
        self._settle(call, "unanswered")

    async def expire(self) -> None:
        """Answer every request whose deadline passed (a task in the
        ``serve()`` block's task group)."""
        while True:
            now = anyio.current_time()
            waiting = [c for c in self._unsettled if c.outcome is None]
            expired = [c for c in waiting if c.deadline <= now]
            for call in expired:
                await self._auto_fail(call, f"no answer within {self.timeout:g} s")
            if expired:
                continue  # requests may have come meanwhile: look again
            # no await from here to the wait: an arrival sets this very event
            self._changed = anyio.Event()
            nearest = min((c.deadline for c in waiting), default=math.inf)
            with anyio.move_on_after(nearest - now):
                await self._changed.wait()

    async def close(self, reason: str, budget: float | None = None) -> None:
        """End serving: answer every request not answered yet (shielded,
        within ``budget`` seconds, the teardown deadline by default) and end
        the iteration. What the budget leaves unanswered counts as lost."""
        self._closed = True
        self._wake.set()
        limit = self._teardown_timeout if budget is None else budget
        with anyio.CancelScope(shield=True), anyio.move_on_after(limit):
            for call in list(self._unsettled):
                await self._auto_fail(call, reason)
        for call in list(self._unsettled):
            if call.outcome is None:  # else an answer is being written now
                self._settle(call, "lost")
        self._queue.clear()

    def fail(self, error: RosBridgeError) -> None:
        """Serving ended in error (the connection is lost for good, or the
        bridge refused the service): the iteration raises ``error`` once the
        requests already queued are read."""
        self._error = error
        self._wake.set()


class ServedServices:
    """The services one client serves, by name, across reconnects: each
    ``serve()`` block's :class:`Serving`, advertised again after a
    reconnect and failed when the connection is lost for good."""

    def __init__(self, teardown_timeout: float, logger: logging.Logger) -> None:
        self._served: dict[str, Serving] = {}
        self._teardown_timeout = teardown_timeout
        self._log = logger

    @asynccontextmanager
    async def serve(
        self,
        name: str,
        service_type: str,
        timeout: float,
        buffer: int,
        current: Callable[[], ServiceHost | None],
    ) -> AsyncIterator[ServiceRequests]:
        """The body of ``Client.serve`` (arguments checked, connected):
        advertise, yield the requests, answer what is open and unadvertise on
        every exit."""
        if name in self._served:
            raise ValueError(f"{name} is served by this client already")
        host = current()
        if host is None:
            raise NotConnected("the connection is not up")
        served = Serving(
            name,
            service_type,
            timeout=timeout,
            buffer=buffer,
            current=current,
            teardown_timeout=self._teardown_timeout,
            logger=self._log,
        )
        self._served[name] = served
        try:
            await host.advertise_service(name, service_type, served)
        except BaseException:
            # the bridge may serve it though (sent, not confirmed): answer the
            # calls that came, then unadvertise (the bridge drops calls still
            # open when the service goes)
            self._served.pop(name, None)
            await self._end(name, served, "the service could not be served", current)
            raise
        try:
            async with anyio.create_task_group() as tg:
                tg.start_soon(served.expire, name=f"rmb-serve-{name}")
                try:
                    yield served.requests
                finally:
                    tg.cancel_scope.cancel()
        finally:
            self._served.pop(name, None)
            await self._end(name, served, "the service stopped serving", current)

    async def _end(
        self,
        name: str,
        served: Serving,
        reason: str,
        current: Callable[[], ServiceHost | None],
    ) -> None:
        """Answer what is open, then unadvertise ``name``: shielded, within
        the teardown deadline, half of it at most for the answers so that the
        unadvertise always has the other half."""
        budget = self._teardown_timeout
        with anyio.CancelScope(shield=True), anyio.move_on_after(budget):
            await served.close(reason, budget / 2)
            host = current()
            if host is not None:
                try:
                    await host.unadvertise_service(name)
                except RosBridgeError as exc:
                    self._log.debug("unadvertising %s failed: %s", name, exc)

    async def restore(self, host: ServiceHost | None) -> None:
        """Advertise every served service on a fresh connection (``host``,
        its serving part), unconfirmed: a refusal arrives later, through the
        new reader, and ends that ``serve()`` block (``on_service_failed``).
        A connection that cannot serve (None) ends every block with
        ``NotSupportedError``."""
        if host is None:
            if self._served:
                self.fail_all(NotSupportedError("the new connection cannot serve services"))
            return
        for name, served in list(self._served.items()):
            if self._served.get(name) is not served:
                continue  # its serve() block ended while this loop awaited
            await host.advertise_service(name, served.service_type, served, confirm=False)

    def fail_all(self, error: RosBridgeError) -> None:
        """Every ``serve()`` iteration raises ``error`` (once the requests
        already queued are read)."""
        for served in self._served.values():
            served.fail(error)
