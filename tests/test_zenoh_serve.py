"""Serving a service over Zenoh (``Client.serve``), called by an independent
rmw_zenoh implementation: zenoh-ros2-sdk service clients
(tests/peers/zenoh_sdk_node.py, role ``client``) through a real eclipse-zenoh
router, fed the official ROS 2 Jazzy interface files offline.

Its calls reach our handler and its answers come back in order; a refused
call reaches it as an error reply; the sdk's discovery sees our service
server (and no more once we stop); two sdk clients at once are each answered;
a call that does not decode (a bare zenoh get) is answered with an error and
counted while the service goes on; and a client of this library calls
another one's served service over the router."""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool
from ros_mobile_bridge.wire import rmw_zenoh as rz

pytest_plugins = ["peers.ros_fixtures"]
pytestmark = pytest.mark.ros
pytest.importorskip("zenoh_ros2_sdk")
zenoh = pytest.importorskip("zenoh")

SET_BOOL = "std_srvs/srv/SetBool"
TRIGGER = "std_srvs/srv/Trigger"


def client_of(sdk: Callable[..., SdkNode], name: str, type_: str, requests: list[Any]) -> SdkNode:
    return sdk("client", "--name", name, "--type", type_, "--requests", json.dumps(requests))


async def answer_set_bool(requests: rmb.ServiceRequests, seen: list[Any]) -> None:
    async for req in requests:
        seen.append(req.args)
        await req.reply(
            SetBool.Response(success=req.args.data, message=f"#{len(seen)} data={req.args.data}")
        )


async def test_an_sdk_client_calls_our_set_bool_and_gets_each_answer_in_order(
    zenoh_router: Any, zenoh_domain: int, sdk: Callable[..., SdkNode]
) -> None:
    seen: list[Any] = []
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.serve("/rmb_set_bool", SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer_set_bool, requests, seen)
        calls = [{"data": True}, {"data": False}, {"data": True}]
        caller = await anyio.to_thread.run_sync(client_of, sdk, "/rmb_set_bool", SET_BOOL, calls)
        assert caller.hashes[SET_BOOL] == type_hash(CodecRegistry(), SET_BOOL)
        await wait_until(lambda: caller.done, timeout=30.0, what="the sdk's calls")
        assert caller.records() == [
            {"response": {"success": True, "message": "#1 data=True"}},
            {"response": {"success": False, "message": "#2 data=False"}},
            {"response": {"success": True, "message": "#3 data=True"}},
        ]
        assert seen == [SetBool.Request(**c) for c in calls]
        assert requests.stats.received == 3 and requests.stats.replied == 3
        tg.cancel_scope.cancel()


ADD_TWO_INTS = "example_interfaces/srv/AddTwoInts"
ADD_TWO_INTS_SRV = "int64 a\nint64 b\n---\nint64 sum\n"


@pytest.fixture
def sdk_with_add_two_ints(
    sdk: Callable[..., SdkNode], ros_share: Path, tmp_path: Path
) -> Callable[..., SdkNode]:
    """sdk nodes whose definitions directory is the official one plus
    ``example_interfaces/srv/AddTwoInts.srv`` (not in the peer environment)."""
    tree = tmp_path / "share"
    tree.mkdir()
    for entry in ros_share.iterdir():
        (tree / entry.name).symlink_to(entry)
    srv_dir = tree / "example_interfaces" / "srv"
    srv_dir.mkdir(parents=True)
    (srv_dir / "AddTwoInts.srv").write_text(ADD_TWO_INTS_SRV)

    def start(role: str, *args: str) -> SdkNode:
        return sdk(role, *args, share=tree)

    return start


async def test_a_registered_service_type_is_served_to_the_sdk(
    zenoh_router: Any, zenoh_domain: int, sdk_with_add_two_ints: Callable[..., SdkNode]
) -> None:
    """AddTwoInts, registered from its .srv text: the sdk computes the same
    RIHS01 hash from the same text, finds our server and gets the sums."""

    async def add(requests: rmb.ServiceRequests) -> None:
        async for req in requests:
            await req.reply({"sum": req.args.a + req.args.b})

    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        client.register_type(ADD_TWO_INTS, ADD_TWO_INTS_SRV)
        async with client.serve("/add_two_ints", ADD_TWO_INTS) as requests:
            async with anyio.create_task_group() as tg:
                tg.start_soon(add, requests)
                calls = [{"a": 1, "b": 2}, {"a": -5, "b": 2**40}, {"a": 0, "b": 0}]
                caller = await anyio.to_thread.run_sync(
                    client_of, sdk_with_add_two_ints, "/add_two_ints", ADD_TWO_INTS, calls
                )
                await wait_until(lambda: caller.done, timeout=30.0, what="the sdk's calls")
                assert caller.records() == [
                    {"response": {"sum": 3}},
                    {"response": {"sum": 2**40 - 5}},
                    {"response": {"sum": 0}},
                ]
                tg.cancel_scope.cancel()
        assert caller.hashes[ADD_TWO_INTS] == type_hash(
            _registry_with(ADD_TWO_INTS, ADD_TWO_INTS_SRV), ADD_TWO_INTS
        )


def _registry_with(name: str, text: str) -> CodecRegistry:
    registry = CodecRegistry()
    registry.add_schema(name, "ros2msg", text)  # a .srv text: X_Request and X_Response
    return registry


async def test_a_refused_call_reaches_the_sdk_client_as_an_error_reply(
    zenoh_router: Any, zenoh_domain: int, sdk: Callable[..., SdkNode]
) -> None:
    async def answer(requests: rmb.ServiceRequests) -> None:
        n = 0
        async for req in requests:
            n += 1
            if n == 2:
                await req.fail("not now")
            else:
                await req.reply({"success": True, "message": f"ok {n}"})

    # (the sdk cannot load std_srvs/srv/Trigger: its request has no field)
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.serve("/rmb_refusing", SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer, requests)
        caller = await anyio.to_thread.run_sync(
            client_of, sdk, "/rmb_refusing", SET_BOOL, [{"data": True}] * 3
        )
        await wait_until(lambda: caller.done, timeout=30.0, what="the sdk's calls")
        assert caller.records() == [
            {"response": {"success": True, "message": "ok 1"}},
            {"error": "not now"},
            {"response": {"success": True, "message": "ok 3"}},
        ]
        assert requests.stats.failed == 1 and requests.stats.replied == 2
        tg.cancel_scope.cancel()


async def test_the_sdk_sees_our_server_until_it_stops_serving(
    zenoh_router: Any, zenoh_domain: int, sdk: Callable[..., SdkNode]
) -> None:
    watcher = await anyio.to_thread.run_sync(lambda: sdk("discover", "--name", "/rmb_seen"))
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        # its first look, before there is anything to see (else it may first see one server)
        await wait_until(lambda: watcher.records(), timeout=30.0, what="the watcher's first look")
        async with client.serve("/rmb_seen", SET_BOOL):
            await wait_until(
                lambda: {"servers": 1, "types": [SET_BOOL]} in watcher.records(),
                timeout=30.0,
                what="discovered",
            )
            assert client.server_info.capabilities.count("serving") == 1
        await wait_until(
            lambda: watcher.records()[-1] == {"servers": 0, "types": []}, timeout=30.0, what="gone"
        )
        assert [r["servers"] for r in watcher.records()] == [0, 1, 0]
        await wait_until(
            lambda: all(s.name != "/rmb_seen" for s in client.services),
            timeout=30.0,
            what="our graph",
        )


async def test_two_sdk_clients_at_once_are_each_answered(
    zenoh_router: Any, zenoh_domain: int, sdk: Callable[..., SdkNode]
) -> None:
    seen: list[Any] = []
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.serve("/rmb_set_bool", SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer_set_bool, requests, seen)
        calls_a = [{"data": True}] * 5
        calls_b = [{"data": False}] * 5
        callers: list[SdkNode] = []

        async def start(calls: list[Any]) -> None:
            node = await anyio.to_thread.run_sync(client_of, sdk, "/rmb_set_bool", SET_BOOL, calls)
            callers.append(node)

        async with anyio.create_task_group() as starting:
            starting.start_soon(start, calls_a)
            starting.start_soon(start, calls_b)
        await wait_until(lambda: all(c.done for c in callers), timeout=30.0, what="both clients")
        for caller in callers:
            answers = [r["response"] for r in caller.records()]
            assert len(answers) == 5
            assert len({a["success"] for a in answers}) == 1  # each got its own answers
            numbers = [int(a["message"].split()[0][1:]) for a in answers]
            assert numbers == sorted(numbers)  # in its own order
        assert sorted(a.data for a in seen) == [False] * 5 + [True] * 5
        assert requests.stats.replied == 10
        tg.cancel_scope.cancel()


async def test_a_request_that_does_not_decode_is_answered_with_an_error_and_counted(
    zenoh_router: Any, zenoh_domain: int, sdk: Callable[..., SdkNode], raw: Any
) -> None:
    seen: list[Any] = []
    key = rz.format_key(
        rz.TopicKey(zenoh_domain, "/rmb_set_bool", SET_BOOL, type_hash(CodecRegistry(), SET_BOOL))
    )
    good = bytes(CodecRegistry().encoder(f"{SET_BOOL}_Request", "cdr")({"data": True}))
    attachment = rz.encode_attachment(1, time.time_ns(), bytes(range(16)))

    def bare_get(payload: bytes, attachment: bytes | None) -> list[tuple[str, bytes, Any]]:
        replies = []
        for reply in raw.get(key, payload=payload, attachment=attachment, timeout=10.0):
            if reply.ok is not None:
                att = reply.ok.attachment
                replies.append(("ok", reply.ok.payload.to_bytes(), att and att.to_bytes()))
            else:
                replies.append(("err", reply.err.payload.to_bytes(), None))
        return replies

    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.serve("/rmb_set_bool", SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer_set_bool, requests, seen)
        garbage = await anyio.to_thread.run_sync(bare_get, b"\xff" * 7, attachment)
        assert len(garbage) == 1 and garbage[0][0] == "err"
        assert b"does not decode" in garbage[0][1]
        bare = await anyio.to_thread.run_sync(bare_get, good, None)
        assert len(bare) == 1 and bare[0][0] == "err" and b"attachment" in bare[0][1]
        assert client.rejections == {"decode": 1, "attachment": 1}
        # a good bare call: the reply carries the request's sequence number
        # and the caller's gid (the attachment rmw_zenoh expects)
        ((kind, payload, reply_attachment),) = await anyio.to_thread.run_sync(
            bare_get, good, attachment
        )
        assert kind == "ok"
        decode = CodecRegistry().decoder(f"{SET_BOOL}_Response", "cdr")
        assert decode(memoryview(payload)) == SetBool.Response(success=True, message="#1 data=True")
        decoded = rz.decode_attachment(reply_attachment)
        assert (decoded.sequence, decoded.gid) == (1, bytes(range(16)))
        assert decoded.timestamp_ns > 0
        # and the service goes on serving an sdk client
        caller = await anyio.to_thread.run_sync(
            client_of, sdk, "/rmb_set_bool", SET_BOOL, [{"data": False}]
        )
        await wait_until(lambda: caller.done, timeout=30.0, what="the sdk's call")
        assert caller.records() == [{"response": {"success": False, "message": "#2 data=False"}}]
        assert requests.stats.received == 2
        tg.cancel_scope.cancel()


async def test_our_client_calls_another_clients_served_service(
    zenoh_router: Any, zenoh_domain: int
) -> None:
    seen: list[Any] = []
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as server,
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as caller,
        server.serve("/rmb_set_bool", SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer_set_bool, requests, seen)
        await wait_until(
            lambda: any(s.name == "/rmb_set_bool" for s in caller.services),
            timeout=30.0,
            what="seen",
        )
        assert [s.type for s in caller.services if s.name == "/rmb_set_bool"] == [SET_BOOL]
        answers = [
            await caller.call_service("/rmb_set_bool", {"data": d}) for d in (True, False, True)
        ]
        assert [a.success for a in answers] == [True, False, True]
        assert [a.message[:2] for a in answers] == ["#1", "#2", "#3"]
        tg.cancel_scope.cancel()

    # a refusal reaches our caller as a ServiceError with the reason, at once
    async def refuse(requests: rmb.ServiceRequests) -> None:
        async for req in requests:
            await req.fail("refused by the test")

    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as server,
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as caller,
        server.serve("/rmb_refuse", TRIGGER) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(refuse, requests)
        await wait_until(
            lambda: any(s.name == "/rmb_refuse" for s in caller.services), timeout=30.0, what="seen"
        )
        with pytest.raises(rmb.ServiceError, match="refused by the test"):
            await caller.call_service("/rmb_refuse", {})
        tg.cancel_scope.cancel()


async def test_a_served_service_is_served_again_after_a_router_restart(
    zenoh_domain: int,
) -> None:
    """The connection's restore advertises the served service on the new
    session (as over rosbridge): a caller reaches it again."""
    from peers.zenoh_router import ZenohRouter

    opts = options(
        zenoh_domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter().start()
    seen: list[Any] = []
    try:
        async with (
            rmb.connect(router.locator, options=opts) as server,
            server.serve("/rmb_set_bool", SET_BOOL) as requests,
            anyio.create_task_group() as tg,
        ):
            tg.start_soon(answer_set_bool, requests, seen)
            async with rmb.connect(router.locator, options=options(zenoh_domain)) as caller:
                await wait_until(
                    lambda: any(s.name == "/rmb_set_bool" for s in caller.services),
                    timeout=30.0,
                    what="1",
                )
                first = await caller.call_service("/rmb_set_bool", {"data": True})
                assert first.message.startswith("#1")
            router.stop()
            await wait_until(
                lambda: server.status == "reconnecting", timeout=30.0, what="reconnecting"
            )
            router = ZenohRouter(port=router.port).start()
            await wait_until(lambda: server.status == "connected", timeout=30.0, what="reconnected")
            async with rmb.connect(router.locator, options=options(zenoh_domain)) as caller:
                await wait_until(
                    lambda: any(s.name == "/rmb_set_bool" for s in caller.services),
                    timeout=30.0,
                    what="2",
                )
                again = await caller.call_service("/rmb_set_bool", {"data": False})
                assert again == SetBool.Response(success=False, message="#2 data=False")
            assert requests.stats.received == 2
            tg.cancel_scope.cancel()
    finally:
        router.stop()


async def test_calls_past_the_open_call_bound_are_refused_and_counted(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    """256 calls may wait for an answer (the session's default bound); the
    ones past it are answered with an error at once and counted as
    ``service_limit``; leaving the block answers the waiting ones."""
    from ros_mobile_bridge.transport._zenoh import DEFAULT_MAX_OPEN_QUERIES

    key = rz.format_key(
        rz.TopicKey(zenoh_domain, "/rmb_busy", SET_BOOL, type_hash(CodecRegistry(), SET_BOOL))
    )
    good = bytes(CodecRegistry().encoder(f"{SET_BOOL}_Request", "cdr")({"data": True}))
    answers: dict[int, list[bytes]] = {}
    total = DEFAULT_MAX_OPEN_QUERIES + 4

    def call(n: int) -> None:
        got: list[bytes] = []

        def on_reply(reply: Any) -> None:
            err = reply.err
            got.append(b"ok" if err is None else err.payload.to_bytes())

        raw.get(
            key,
            zenoh.handlers.Callback(on_reply, lambda: answers.__setitem__(n, got)),
            payload=good,
            attachment=rz.encode_attachment(n + 1, time.time_ns(), bytes(16)),
            timeout=30.0,
        )

    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        async with client.serve("/rmb_busy", SET_BOOL, buffer=1000, timeout=60) as requests:
            for n in range(total):  # nobody reads the requests: they all wait
                call(n)
            await wait_until(
                lambda: requests.stats.received == DEFAULT_MAX_OPEN_QUERIES,
                timeout=30.0,
                what="queued",
            )
            await wait_until(lambda: len(answers) == 4, timeout=30.0, what="the refused calls")
            refused = b"256 calls already wait for an answer"
            assert all(replies == [refused] for replies in answers.values())
            await wait_until(
                lambda: client.rejections.get("service_limit") == 4, timeout=30.0, what="counted"
            )
        await wait_until(lambda: len(answers) == total, timeout=30.0, what="every call answered")
    stopped = [r for r in answers.values() if r == [b"the service stopped serving"]]
    assert len(stopped) == DEFAULT_MAX_OPEN_QUERIES
    assert requests.stats.received == DEFAULT_MAX_OPEN_QUERIES
