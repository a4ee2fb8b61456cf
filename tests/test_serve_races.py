"""``serve()``'s promise, every request answered exactly once, under the
races a real bridge cannot be made to produce on demand: an answer cancelled
before or after its write, a stall longer than the deadline, a refusal that
arrives after the advertisement returned, an advertisement that fails after
its frame was sent. The serving side runs against a stub backend (it records
what would be written) or a rosbridge backend on a fake socket; the
behaviour against the real bridge is in test_serve.py."""

from __future__ import annotations

import json
import logging
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from ros_mobile_bridge._core._serve import ServedServices, Serving
from ros_mobile_bridge.adapters import _rosbridge
from ros_mobile_bridge.wire import rosbridge as rb

NAME = "/rmb_served"
SETBOOL = "std_srvs/srv/SetBool"


class StubBackend:
    """Writes answers to ``written`` under a lock the test can hold (the
    checkpoint before a real write: the websocket's send lock). With
    ``slow_write``, the write itself waits for ``release``, shielded, as a
    real socket write is."""

    def __init__(self, *, slow_write: bool = False) -> None:
        self.lock = anyio.Lock()
        self.written: list[tuple[str, Any, bool]] = []
        self.slow_write = slow_write
        self.release = anyio.Event()

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        async with self.lock:
            if self.slow_write:
                with anyio.CancelScope(shield=True):
                    await self.release.wait()
            self.written.append((request_id, values, result))


def served(backend: Any, *, timeout: float = 30.0, buffer: int = 16) -> Serving:
    """The engine of one ``serve()`` block; ``.requests`` is what the
    consumer iterates."""
    return Serving(
        NAME,
        SETBOOL,
        timeout=timeout,
        buffer=buffer,
        current=lambda: backend,
        teardown_timeout=2.0,
        logger=logging.getLogger("ros_mobile_bridge"),
    )


async def cancelled_while_blocked(call: Any) -> None:
    """Run ``call`` until it blocks, then cancel it."""
    async with anyio.create_task_group() as tg:
        tg.start_soon(call)
        await anyio.wait_all_tasks_blocked()
        tg.cancel_scope.cancel()


async def test_moving_on_cancelled_before_the_write_leaves_the_request_to_close() -> None:
    backend = StubBackend()
    serving = served(backend)
    await serving.on_service_request(backend, "a", {"data": True})  # type: ignore[arg-type]
    await serving.on_service_request(backend, "b", {"data": False})  # type: ignore[arg-type]
    first = await serving.requests.__anext__()
    async with backend.lock:  # the automatic answer to "a" waits for the socket
        await cancelled_while_blocked(serving.requests.__anext__)
    assert not first.answered  # not claimed for good: nothing was written
    await serving.close("closing")
    assert backend.written == [("a", "closing", False), ("b", "closing", False)]
    stats = serving.requests.stats
    assert (stats.received, stats.unanswered, stats.lost, stats.pending) == (2, 2, 0, 0)


async def test_a_reply_cancelled_before_the_write_stays_open() -> None:
    backend = StubBackend()
    serving = served(backend)
    await serving.on_service_request(backend, "a", {"data": True})  # type: ignore[arg-type]
    req = await serving.requests.__anext__()
    async with backend.lock:
        await cancelled_while_blocked(lambda: req.reply({"success": True}))
    assert req.outcome is None and serving.requests.stats.lost == 0
    await req.reply({"success": True, "message": "second try"})  # still the handler's
    assert backend.written == [("a", {"success": True, "message": "second try"}, True)]
    stats = serving.requests.stats
    assert (stats.replied, stats.lost, stats.pending) == (1, 0, 0)


async def test_a_reply_cancelled_before_the_write_is_answered_when_the_block_ends() -> None:
    backend = StubBackend()
    serving = served(backend)
    await serving.on_service_request(backend, "a", {"data": True})  # type: ignore[arg-type]
    req = await serving.requests.__anext__()
    async with backend.lock:
        await cancelled_while_blocked(lambda: req.reply({"success": True}))
    await serving.close("closing")
    assert backend.written == [("a", "closing", False)]
    assert req.outcome == "unanswered"
    stats = serving.requests.stats
    assert (stats.unanswered, stats.lost, stats.pending) == (1, 0, 0)


async def test_a_reply_written_counts_as_replied_though_cancelled_meanwhile() -> None:
    backend = StubBackend(slow_write=True)
    serving = served(backend)
    await serving.on_service_request(backend, "a", {"data": True})  # type: ignore[arg-type]
    req = await serving.requests.__anext__()
    returned: list[bool] = []

    async def reply() -> None:
        await req.reply({"success": True})
        returned.append(True)
        await anyio.sleep(3600)  # the cancellation lands here

    async with anyio.create_task_group() as tg:
        tg.start_soon(reply)
        await anyio.wait_all_tasks_blocked()  # in the shielded write
        tg.cancel_scope.cancel()
        backend.release.set()
    assert returned == [True]
    assert backend.written == [("a", {"success": True}, True)]
    assert req.outcome == "replied"
    await serving.close("closing")
    stats = serving.requests.stats
    assert (stats.replied, stats.unanswered, stats.lost, stats.pending) == (1, 0, 0, 0)


async def test_requests_expired_while_queued_do_not_fill_the_buffer() -> None:
    backend = StubBackend()
    serving = served(backend, timeout=0.05, buffer=2)
    async with anyio.create_task_group() as tg:
        tg.start_soon(serving.expire)
        await serving.on_service_request(backend, "a", {})  # type: ignore[arg-type]
        await serving.on_service_request(backend, "b", {})  # type: ignore[arg-type]
        # the consumer stalls past the deadline
        await wait_until(lambda: serving.requests.stats.unanswered >= 2, 5, what="the expiry")
        await serving.on_service_request(backend, "c", {})  # type: ignore[arg-type]
        await serving.on_service_request(backend, "d", {})  # type: ignore[arg-type]
        assert serving.requests.stats.overflowed == 0
        with anyio.fail_after(5):
            first = await serving.requests.__anext__()  # the expired ones are not handed out
        await first.reply({"success": True})
        tg.cancel_scope.cancel()
    assert first.id == "c"
    await serving.close("closing")
    assert [w[0] for w in backend.written] == ["a", "b", "c", "d"]
    stats = serving.requests.stats
    assert (stats.received, stats.replied, stats.unanswered, stats.overflowed) == (4, 1, 3, 0)


# -- the rosbridge backend on a fake socket ---------------------------------------------


class FakeSocket:
    def __init__(self) -> None:
        self.sent: list[dict[str, Any]] = []
        self.closed = False

    async def send(self, message: str | bytes) -> None:
        await anyio.lowlevel.checkpoint()
        self.sent.append(json.loads(message))


async def no_round_trip() -> None:
    pass  # nobody answers on a fake socket


def rosbridge_backend() -> tuple[_rosbridge.RosbridgeAdapter, FakeSocket]:
    ws = FakeSocket()
    return _rosbridge.RosbridgeAdapter(ws, rmb.ClientOptions()), ws  # type: ignore[arg-type]


@pytest.mark.parametrize("confirm", [True, False])
async def test_a_refusal_after_the_advertisement_ends_the_iteration(
    confirm: bool, monkeypatch: pytest.MonkeyPatch
) -> None:
    backend, _ws = rosbridge_backend()

    async def confirmed(name: str, served: Any) -> None:
        pass  # the graph showed it (a real bridge may refuse only later)

    monkeypatch.setattr(backend.serving, "_confirm_served", confirmed)
    serving = served(backend.serving)
    await backend.serving.advertise_service(NAME, "nosuch_pkg/srv/Nope", serving, confirm=confirm)
    served_id = backend.serving._served[NAME].id
    backend._on_status(rb.Status("error", "unknown service type nosuch_pkg/srv/Nope", served_id))
    with anyio.fail_after(5), pytest.raises(rmb.SchemaError, match="nosuch_pkg"):
        await serving.requests.__anext__()
    assert NAME not in backend.serving._served  # refused: nothing to unadvertise


async def test_another_client_refusal_after_a_restore_is_a_service_error() -> None:
    backend, _ws = rosbridge_backend()
    serving = served(backend.serving)
    await backend.serving.advertise_service(NAME, SETBOOL, serving, confirm=False)
    served_id = backend.serving._served[NAME].id
    backend._on_status(rb.Status("error", "served by another client", served_id))
    with anyio.fail_after(5), pytest.raises(rmb.ServiceError, match="another client"):
        await serving.requests.__anext__()


@pytest.mark.parametrize("how", ["timeout", "cancelled"])
async def test_an_advertisement_failing_after_its_frame_is_unadvertised(
    how: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    backend, ws = rosbridge_backend()

    async def unconfirmed(name: str, served: Any) -> None:
        if how == "timeout":
            raise rmb.ServiceError(name, "the bridge did not confirm serving it")
        await anyio.sleep(3600)

    monkeypatch.setattr(backend.serving, "_confirm_served", unconfirmed)
    monkeypatch.setattr(backend._calls, "round_trip", no_round_trip)
    serving = served(backend.serving)
    backend_ids: list[str] = []
    advertise = backend._engine.advertise_service

    def remember(service: str, type: str, *, id: str) -> str:
        backend_ids.append(id)
        return advertise(service, type, id=id)

    monkeypatch.setattr(backend._engine, "advertise_service", remember)
    if how == "timeout":
        with pytest.raises(rmb.ServiceError):
            await backend.serving.advertise_service(NAME, SETBOOL, serving)
    else:
        with anyio.move_on_after(0.05):
            await backend.serving.advertise_service(NAME, SETBOOL, serving)
    # maybe served: calls still reach the handler until the caller (the
    # client, after answering them) unadvertises
    await backend._handle(rb.ServiceRequest("q1", NAME, {"data": True}))
    assert serving.requests.stats.received == 1
    await serving.close("closing")
    await backend.serving.unadvertise_service(NAME)
    assert [(m["op"], m.get("id"), m.get("values")) for m in ws.sent][1:] == [
        ("service_response", "q1", "closing"),
        ("unadvertise_service", backend_ids[0], None),
    ]
    assert NAME not in backend.serving._served


async def test_a_refused_advertisement_is_not_unadvertised(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    backend, ws = rosbridge_backend()

    async def refused(name: str, served: Any) -> None:
        served.error = "served by another client"

    monkeypatch.setattr(backend.serving, "_confirm_served", refused)
    with pytest.raises(rmb.ServiceError, match="another client"):
        await backend.serving.advertise_service(NAME, SETBOOL, served(backend.serving))
    # the name may be the other client's: no unadvertise_service for it
    assert [m["op"] for m in ws.sent] == ["advertise_service"]


# -- the client's side, on a stub backend ----------------------------------------------


class ClientStub:
    """Enough of a backend for ``Client``'s serving paths: advertisements
    are recorded; an answer's write never completes (a stuck socket)."""

    def __init__(self) -> None:
        self.topics: list[Any] = []
        self.services: list[Any] = []
        self.advertised: list[str] = []
        self.handlers: dict[str, Any] = {}  # what the reader hands calls to
        self.unadvertised: list[str] = []
        self.gate: anyio.Event | None = None

    def publishing(self) -> dict[str, str]:
        return {}

    async def advertise_service(
        self, name: str, service_type: str, handler: Any, *, confirm: bool = True
    ) -> None:
        self.advertised.append(name)
        self.handlers[name] = handler
        if self.gate is not None:
            await self.gate.wait()

    async def unadvertise_service(self, name: str) -> None:
        await anyio.lowlevel.checkpoint()
        self.unadvertised.append(name)

    async def respond_service(self, name: str, request_id: str, values: Any, result: bool) -> None:
        await anyio.sleep(3600)


def services_of(teardown_timeout: float = 2.0) -> ServedServices:
    """The client's registry of served services (``Connection.served``)."""
    return ServedServices(teardown_timeout, logging.getLogger("ros_mobile_bridge"))


async def test_leaving_the_block_unadvertises_though_the_answers_take_the_whole_budget() -> None:
    backend = ClientStub()
    services = services_of(teardown_timeout=0.3)
    current: Any = lambda: backend  # noqa: E731
    async with services.serve(NAME, SETBOOL, 30.0, 16, current) as requests:
        await backend.handlers[NAME].on_service_request(backend, "q", {"data": True})
    assert backend.unadvertised == [NAME]
    stats = requests.stats
    assert (stats.received, stats.lost, stats.pending) == (1, 1, 0)  # never written


async def test_a_restore_skips_a_service_whose_block_ended_meanwhile() -> None:
    old = ClientStub()
    services = services_of()
    first, second = served(old), served(old)
    services._served.update({"/first": first, "/second": second})
    new: Any = ClientStub()
    new.gate = anyio.Event()
    async with anyio.create_task_group() as tg:
        tg.start_soon(services.restore, new)
        await anyio.wait_all_tasks_blocked()  # advertising /first on the new connection
        del services._served["/second"]  # that serve() block ended meanwhile
        new.gate.set()
    assert new.advertised == ["/first"]
