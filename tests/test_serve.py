"""Serving a service over rosbridge (``Client.serve``), against a real ROS 2
graph behind rosbridge_server_rs: a ROS node (``ros_graph_node.py``'s
``call``) and a second client calling through the bridge are the callers.

rosbridge_server_rs cannot hand a ``result: false`` on to a ROS caller (ROS 2
services have no error response): it answers our frame with a status error
("request will time out") and the caller fails at its own timeout. The tests
check both ends: the bridge's word that our answer was ``result: false``, and
the caller's failure."""

from __future__ import annotations

import itertools
import json
import logging
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import rosbridge_options as options
from _util import wait_until
from peers.foxglove_sdk import SdkServer
from peers.rosbridge import RosBridge, RosGraph
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool, Trigger
from ros_mobile_bridge.wire import rosbridge as rb

pytest_plugins = ["peers.ros_fixtures"]
pytestmark = pytest.mark.peer

SETBOOL = "std_srvs/srv/SetBool"
TRIGGER = "std_srvs/srv/Trigger"
LOGGER = "ros_mobile_bridge"
_unique = itertools.count()


def unique(name: str) -> str:
    return f"{name}_{next(_unique)}"


async def ros_call(
    graph: RosGraph, service: str, srv_type: str, args: dict[str, Any], timeout: float = 5.0
) -> Any:
    """Call ``service`` from the ROS graph node (a real rclpy client)."""
    request = {"cmd": "call", "service": service, "type": srv_type, "args": args}
    request["timeout"] = timeout
    return await anyio.to_thread.run_sync(lambda: graph.command(request, timeout=2 * timeout + 5))


def bridge_said_result_false(caplog: pytest.LogCaptureFixture, request_id: str) -> bool:
    """rosbridge_server_rs received our ``result: false`` for ``request_id``
    (its answer: "ROS services cannot carry an error response")."""
    return any(
        request_id in r.getMessage() and "cannot carry an error response" in r.getMessage()
        for r in caplog.records
    )


# -- arguments ------------------------------------------------------------------------


async def test_bad_arguments_raise_at_once(rosbridge: RosBridge) -> None:
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        with pytest.raises(ValueError, match="absolute ROS name"):
            robot.serve("no_slash", SETBOOL)
        with pytest.raises(ValueError, match="service type"):
            robot.serve("/x", "std_msgs/msg/String")
        with pytest.raises(ValueError, match="ROS type"):
            robot.serve("/x", "SetBool")
        with pytest.raises(TypeError):
            robot.serve("/x", SETBOOL, timeout="soon")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="positive"):
            robot.serve("/x", SETBOOL, timeout=0)
        with pytest.raises(ValueError, match="buffer"):
            robot.serve("/x", SETBOOL, buffer=0)
        name = unique("/rmb_served")
        async with robot.serve(name, SETBOOL):
            with pytest.raises(ValueError, match="already"):
                async with robot.serve(name, SETBOOL):
                    pytest.fail("served twice")


async def test_an_unknown_type_is_refused_by_the_bridge(rosbridge: RosBridge) -> None:
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        with pytest.raises(rmb.SchemaError, match="nosuch_pkg"):
            async with robot.serve(unique("/rmb_served"), "nosuch_pkg/srv/Nope"):
                pytest.fail("served an unknown type")
        # the name is free again, and the connection fine
        assert (await robot.call_service("/set_flag", {"data": True})).success is True


async def test_foxglove_cannot_serve() -> None:
    with SdkServer() as sdk:
        async with rmb.connect(sdk.url, options=options()) as robot:
            with pytest.raises(rmb.NotSupportedError, match="Foxglove"):
                async with robot.serve("/rmb_served", SETBOOL):
                    pytest.fail("served over Foxglove")


# -- answering ------------------------------------------------------------------------


async def test_a_ros_call_reaches_us_and_the_reply_reaches_the_ros_caller(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    name = unique("/rmb_served")
    seen: list[rmb.ServiceRequest] = []
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        async with robot.serve(name, SETBOOL) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    seen.append(req)
                    await req.reply(SetBool.Response(success=True, message=f"got {req.args.data}"))

            tg.start_soon(answer)
            first = await ros_call(ros_graph, name, SETBOOL, {"data": True})
            second = await ros_call(ros_graph, name, SETBOOL, {"data": False})
            tg.cancel_scope.cancel()
        stats = requests.stats
    assert first == {"response": {"success": True, "message": "got True"}}
    assert second == {"response": {"success": True, "message": "got False"}}
    assert [r.args for r in seen] == [SetBool.Request(data=True), SetBool.Request(data=False)]
    assert all(r.service == name and r.id and r.outcome == "replied" for r in seen)
    assert (stats.received, stats.replied, stats.pending) == (2, 2, 0)


async def test_a_second_client_calls_through_the_bridge(rosbridge: RosBridge) -> None:
    name = unique("/rmb_served")
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as server,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as caller,
    ):
        async with server.serve(name, TRIGGER) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    await req.reply({"success": True, "message": "triggered"})

            tg.start_soon(answer)
            reply = await caller.call_service(name, {}, timeout=5)
            tg.cancel_scope.cancel()
    assert reply == Trigger.Response(success=True, message="triggered")


async def test_a_reply_that_does_not_fit_the_type_raises_and_stays_answerable(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    name = unique("/rmb_served")
    errors: list[BaseException] = []
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        async with robot.serve(name, SETBOOL) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    with pytest.raises(ValueError, match="nope") as caught:
                        await req.reply({"nope": 1})
                    errors.append(caught.value)
                    assert not req.answered
                    with pytest.raises(TypeError):
                        await req.reply(["not", "a", "dict"])  # type: ignore[arg-type]
                    await req.reply({"success": True})

            tg.start_soon(answer)
            result = await ros_call(ros_graph, name, SETBOOL, {"data": True})
            tg.cancel_scope.cancel()
    assert result == {"response": {"success": True, "message": ""}}
    assert len(errors) == 1


async def test_fail_gives_the_caller_a_failure(
    rosbridge: RosBridge, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, LOGGER)
    name = unique("/rmb_served")
    ids: list[str] = []
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as server,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as caller,
    ):
        async with server.serve(name, SETBOOL) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    ids.append(req.id)
                    await req.fail("flag hardware offline")
                    with pytest.raises(rmb.ServiceError, match="answered already"):
                        await req.reply({"success": True})

            tg.start_soon(answer)
            with pytest.raises(rmb.ServiceError) as caught:
                await caller.call_service(name, {"data": True}, timeout=2)
            await wait_until(lambda: bridge_said_result_false(caplog, ids[0]), 5)
            tg.cancel_scope.cancel()
        assert requests.stats.failed == 1
    # rosbridge_server_rs cannot pass the reason on: the caller times out
    assert "Timeout exceeded" in str(caught.value)


async def test_an_unanswered_request_is_answered_false_when_the_block_exits(
    rosbridge: RosBridge, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, LOGGER)
    name = unique("/rmb_served")
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as server,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as caller,
        anyio.create_task_group() as tg,
    ):
        outcome: list[BaseException] = []

        async def call() -> None:
            try:
                # routed through the ROS graph to a just-advertised service, which
                # can take seconds on a loaded machine; the bridge cannot carry the
                # failed answer, so the call ends at this timeout
                await caller.call_service(name, {"data": True}, timeout=8)
            except rmb.ServiceError as exc:
                outcome.append(exc)

        async with server.serve(name, SETBOOL) as requests:
            tg.start_soon(call)
            with anyio.fail_after(5):
                req = await requests.__anext__()
            assert not req.answered
        # the block ended with the request open: answered false, on the wire
        assert req.outcome == "unanswered"
        assert requests.stats.unanswered == 1
        await wait_until(lambda: bridge_said_result_false(caplog, req.id), 5)
        await wait_until(lambda: bool(outcome), 10)
    assert isinstance(outcome[0], rmb.ServiceError)


async def test_moving_on_and_the_deadline_answer_false(
    rosbridge: RosBridge, ros_graph: RosGraph, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, LOGGER)
    name = unique("/rmb_served")
    taken: list[rmb.ServiceRequest] = []
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        async with robot.serve(name, SETBOOL, timeout=0.5) as requests:
            async with anyio.create_task_group() as tg:
                tg.start_soon(ros_call, ros_graph, name, SETBOOL, {"data": True}, 1.0)
                tg.start_soon(ros_call, ros_graph, name, SETBOOL, {"data": False}, 1.0)
                with anyio.fail_after(10):
                    taken.append(await requests.__anext__())  # never answered
                    taken.append(await requests.__anext__())  # moving on answered the first
                assert taken[0].outcome == "unanswered"
                # the second one waits for its deadline
                await wait_until(lambda: taken[1].answered, 5)
                assert taken[1].outcome == "unanswered"
                with pytest.raises(rmb.ServiceError, match="answered already"):
                    await taken[1].reply({"success": True})
            stats = requests.stats
    assert (stats.received, stats.unanswered, stats.pending) == (2, 2, 0)
    for req in taken:
        assert bridge_said_result_false(caplog, req.id)


async def test_overflow_is_answered_false_and_counted(
    rosbridge: RosBridge, ros_graph: RosGraph, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.INFO, LOGGER)
    name = unique("/rmb_served")
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        async with robot.serve(name, SETBOOL, buffer=1) as requests:
            async with anyio.create_task_group() as tg:
                for value in (True, False, True):
                    tg.start_soon(ros_call, ros_graph, name, SETBOOL, {"data": value}, 1.0)
                await wait_until(lambda: requests.stats.received == 3, 10)
                assert requests.stats.overflowed == 2
                with anyio.fail_after(5):
                    req = await requests.__anext__()
                await req.reply({"success": True})
            stats = requests.stats
    assert (stats.received, stats.replied, stats.overflowed, stats.pending) == (3, 1, 2, 0)
    refusals = [r for r in caplog.records if "cannot carry an error response" in r.getMessage()]
    assert len(refusals) == 2


async def test_a_serve_cancelled_while_confirming_answers_its_calls_and_unadvertises(
    rosbridge: RosBridge,
    ros_graph: RosGraph,
    caplog: pytest.LogCaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # The advertise frame is out and the bridge routes calls here, but the
    # confirmation has not come when the caller gives up: the calls that came
    # meanwhile are answered, and the bridge stops routing the name here.
    caplog.set_level(logging.INFO, LOGGER)
    name = unique("/rmb_served")
    failures: list[rmb.ServiceError] = []
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as server,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as caller,
    ):
        confirming = anyio.Event()
        handlers: list[Any] = []  # the serve() block's engine, as the adapter holds it

        async def never_confirmed(service: str, served: Any) -> None:
            handlers.append(served.handler)
            confirming.set()
            await anyio.sleep(3600)

        monkeypatch.setattr(server._conn.adapter.serving, "_confirm_served", never_confirmed)
        entering = anyio.CancelScope()

        async def enter() -> None:
            with entering:
                async with server.serve(name, SETBOOL):
                    pytest.fail("entered without a confirmation")

        async def call() -> None:
            try:
                # routed through the ROS graph to a just-advertised service, which
                # can take seconds on a loaded machine; the bridge cannot carry the
                # failed answer, so the call ends at this timeout
                await caller.call_service(name, {"data": True}, timeout=8)
            except rmb.ServiceError as exc:
                failures.append(exc)

        async with anyio.create_task_group() as tg:
            tg.start_soon(enter)
            with anyio.fail_after(10):
                await confirming.wait()
            (requests,) = handlers
            # the bridge routes a call only once its service is on the ROS
            # graph; a call sent before that may never reach the server
            await caller.wait_for_service(name, timeout=10)
            tg.start_soon(call)
            await wait_until(lambda: requests.stats.received == 1, 10, "the call routed here")
            entering.cancel()
        assert entering.cancelled_caught
        stats = requests.stats
        assert (stats.received, stats.unanswered, stats.pending) == (1, 1, 0)
        assert any("cannot carry an error response" in r.getMessage() for r in caplog.records)
        assert len(failures) == 1
        # the bridge routes the name here no more
        after = await ros_call(ros_graph, name, SETBOOL, {"data": True}, timeout=1.0)
        assert after == {"timeout": True, "available": False}


async def test_unadvertised_on_exit(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    name = unique("/rmb_served")
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as robot:
        async with robot.serve(name, TRIGGER) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    await req.reply({"success": True, "message": "up"})

            tg.start_soon(answer)
            assert await ros_call(ros_graph, name, TRIGGER, {}) == {
                "response": {"success": True, "message": "up"}
            }
            tg.cancel_scope.cancel()
        # served no more: a ROS caller finds no server
        after = await ros_call(ros_graph, name, TRIGGER, {}, timeout=1.0)
        assert after == {"timeout": True, "available": False}
        # and the name can be served again by this client
        async with robot.serve(name, TRIGGER):
            pass


async def test_served_again_after_a_reconnect(rosbridge_factory: Any, ros_graph: RosGraph) -> None:
    bridge = rosbridge_factory()
    port = bridge.port
    name = unique("/rmb_served")
    policy = rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.5)
    async with rmb.connect(
        bridge.url, protocol="rosbridge", options=options(reconnect=policy)
    ) as robot:
        async with robot.serve(name, TRIGGER) as requests, anyio.create_task_group() as tg:

            async def answer() -> None:
                async for req in requests:
                    await req.reply({"success": True, "message": "still here"})

            tg.start_soon(answer)
            await anyio.to_thread.run_sync(bridge.stop)
            await wait_until(lambda: robot.status == "reconnecting", 10)
            await anyio.to_thread.run_sync(lambda: rosbridge_factory(port=port))
            await wait_until(lambda: robot.status == "connected", 30)
            # a service the restarted bridge just created: its request path to
            # a ROS client can match before its response path, and then the
            # bridge refuses our answer ("client will not receive response",
            # seen in CI): the caller times out and calls again
            with anyio.fail_after(60):
                while "timeout" in (reply := await ros_call(ros_graph, name, TRIGGER, {}, 3.0)):
                    pass
            tg.cancel_scope.cancel()
    assert reply == {"response": {"success": True, "message": "still here"}}


# -- the wire engine (sans-IO) -------------------------------------------------------


def test_the_engine_reads_a_forwarded_call_and_builds_the_ops() -> None:
    engine = rb.RosbridgeEngine()
    frame = '{"op":"call_service","id":"service_request:/a:1","service":"/a","args":{"data":true}}'
    assert engine.receive_text(frame) == [
        rb.ServiceRequest("service_request:/a:1", "/a", {"data": True})
    ]
    no_args = engine.receive_text('{"op":"call_service","id":"q","service":"/a"}')
    assert no_args == [rb.ServiceRequest("q", "/a", {})]
    for bad in (
        '{"op":"call_service","service":"/a"}',  # no id: cannot be answered
        '{"op":"call_service","id":"q","service":"/a","args":[1]}',
        '{"op":"call_service","id":"q"}',
    ):
        (event,) = engine.receive_text(bad)
        assert isinstance(event, rb.ProtocolViolation)
    assert json.loads(rb.RosbridgeEngine.advertise_service("/a", SETBOOL, id="x")) == {
        "op": "advertise_service",
        "id": "x",
        "service": "/a",
        "type": SETBOOL,
    }
    assert json.loads(rb.RosbridgeEngine.unadvertise_service("/a", id="x")) == {
        "op": "unadvertise_service",
        "id": "x",
        "service": "/a",
    }
    ok = rb.RosbridgeEngine.service_response("/a", b'{"success":true}', id="q", result=True)
    assert json.loads(ok) == {
        "op": "service_response",
        "id": "q",
        "service": "/a",
        "result": True,
        "values": {"success": True},
    }
    failed = rb.RosbridgeEngine.service_response("/a", json.dumps("no"), id="q", result=False)
    assert json.loads(failed)["values"] == "no"
    with pytest.raises(TypeError):
        rb.RosbridgeEngine.service_response("/a", "{}", id="q", result=1)  # type: ignore[arg-type]
