"""One error contract for every call, on every transport (docs/errors.md).

Each caller mistake and each robot refusal is driven through each call on
each transport, against real peers: the demo robot (the official Foxglove
SDK server), rosbridge_server_rs on a ROS 2 Jazzy graph, and zenoh-ros2-sdk
nodes through an eclipse-zenoh router. Each test asserts the class and that
the text names the field, the name or the call.

* a message, request, goal or served reply that does not fit its type:
  ``MessageError`` (also a ``DecodeError`` and a ``ValueError``), nothing
  sent;
* a parameter the robot refuses or does not have: ``ParameterError`` with a
  reason per name (the robot's own where it gives one), after applying what
  it accepted;
* ``wait_for_topic`` / ``wait_for_service``, the warning for a subscription
  to a name the robot does not offer, and the hint for ``async for`` over
  ``subscribe(...)`` without ``async with``."""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import rosbridge_options, wait_until, zenoh_options
from peers.rosbridge import RosBridge, RosGraph
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.demo import DemoRobot
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool

pytest_plugins = ["peers.ros_fixtures"]

LOGGER = "ros_mobile_bridge"
TWIST = "geometry_msgs/msg/Twist"
SET_BOOL = "std_srvs/srv/SetBool"
FIB = "test_msgs/action/Fibonacci"


fox_options = partial(rmb.ClientOptions, reconnect=None)


def assert_misfit(exc: rmb.MessageError, call: str, type_name: str, field: str) -> None:
    """One class, every base an older ``except`` used, and the words."""
    assert isinstance(exc, rmb.MessageError)
    assert isinstance(exc, rmb.DecodeError) and isinstance(exc, ValueError)
    assert isinstance(exc, rmb.RosBridgeError)
    assert exc.call == call and exc.field == field and exc.type_name.endswith(type_name)
    assert str(exc).startswith(f"{call}: cannot encode ")
    assert repr(field) in str(exc)


# -- Foxglove: the demo robot ---------------------------------------------------------------


async def test_foxglove_publish_and_call_misfits_are_one_class(robot: DemoRobot) -> None:
    before = len(robot.received_cmd_vel())
    async with rmb.connect(robot.url, options=fox_options()) as client:
        with pytest.raises(rmb.MessageError) as pub:
            await client.publish("/cmd_vel", TWIST, {"linear": {"q": 1.0}})
        assert_misfit(pub.value, "publish /cmd_vel", "Twist", "linear.q")
        with pytest.raises(rmb.MessageError) as wrong:
            await client.publish("/cmd_vel", TWIST, {"linear": {"x": "fast"}})
        assert_misfit(wrong.value, "publish /cmd_vel", "Twist", "linear.x")
        with pytest.raises(rmb.MessageError) as call:
            await client.call_service("/set_led", {"dat": True})
        assert_misfit(call.value, "call_service /set_led", "SetBool_Request", "dat")
        assert "unknown field" in call.value.reason
        # the caller's other mistakes: a type name that is unknown, a malformed name
        with pytest.raises(rmb.SchemaError, match="Twst"):
            await client.publish("/cmd_vel", "geometry_msgs/msg/Twst", {})
        with pytest.raises(ValueError, match="absolute ROS name"):
            await client.call_service("set_led", {})
        # a capability the transport lacks
        with pytest.raises(rmb.NotSupportedError):
            async with client.send_action_goal("/fibonacci", FIB, {"order": 1}):
                pass
        with pytest.raises(rmb.NotSupportedError):
            async with client.serve("/rmb_contract_served", SET_BOOL):
                pass
        assert await client.call_service("/set_led", {"data": False}) == SetBool.Response(
            success=True, message="led off"
        )
    assert robot.received_cmd_vel()[before:] == []  # nothing that did not fit was sent


async def test_foxglove_parameter_refusals_raise_with_what_the_robot_kept(
    robot: DemoRobot,
) -> None:
    async with rmb.connect(robot.url, options=fox_options()) as client:
        await client.set_parameters({"max_speed": 0.8})
        with pytest.raises(rmb.ParameterError) as refused:
            await client.set_parameters({"max_speed": "fast", "robot_name": "rover"})
        # the accepted one is applied, the refused one named with what the robot kept
        assert list(refused.value.reasons) == ["max_speed"]
        assert "kept 0.8" in refused.value.reasons["max_speed"]
        assert refused.value.values == {"max_speed": 0.8, "robot_name": "rover"}
        assert robot.parameters["robot_name"] == "rover"
        assert "'max_speed'" in str(refused.value)
        with pytest.raises(rmb.ParameterError) as missing:
            await client.get_parameters(["max_sped", "max_speed"])
        assert list(missing.value.reasons) == ["max_sped"]
        assert missing.value.reasons["max_sped"] == "not found; nearest: max_speed"
        assert missing.value.values == {"max_speed": 0.8}
        assert isinstance(missing.value, rmb.RosBridgeError)
        assert await client.get_parameters(["max_speed"]) == {"max_speed": 0.8}


async def test_wait_for_topic_and_service(robot: DemoRobot) -> None:
    async with rmb.connect(robot.url, options=fox_options()) as client:
        info = await client.wait_for_topic("/odom", timeout=10)
        assert (info.name, info.schema_name) == ("/odom", "nav_msgs/msg/Odometry")
        service = await client.wait_for_service("/set_led")
        assert (service.name, service.type) == ("/set_led", SET_BOOL)
        with pytest.raises(TimeoutError, match=r"topic /odm within 0\.2 s; nearest: /odom"):
            await client.wait_for_topic("/odm", timeout=0.2)
        with pytest.raises(TimeoutError, match="nearest: /set_led"):
            await client.wait_for_service("/set_le", timeout=0.2)
        with pytest.raises(ValueError, match="absolute ROS name"):
            await client.wait_for_topic("odom")
        with pytest.raises(ValueError, match="timeout"):
            await client.wait_for_topic("/odom", timeout=-1)


async def test_wait_for_topic_raises_not_connected_when_the_connection_ends() -> None:
    demo = DemoRobot()
    demo.start()
    caught: list[rmb.NotConnected] = []
    try:
        async with rmb.connect(demo.url, options=fox_options()) as client:

            async def wait() -> None:
                with pytest.raises(rmb.NotConnected) as lost:
                    await client.wait_for_topic("/never", timeout=30)
                caught.append(lost.value)

            async with anyio.create_task_group() as tg:
                tg.start_soon(wait)
                await anyio.wait_all_tasks_blocked()  # the wait for /never began
                await anyio.to_thread.run_sync(demo.stop)
    finally:
        demo.stop()
    assert len(caught) == 1
    assert "lost for good before topic /never appeared" in str(caught[0])


async def test_a_subscription_to_a_name_not_offered_warns_once_with_the_nearest(
    robot: DemoRobot, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, LOGGER)
    options = fox_options(unknown_topic_warning=0.3)
    async with rmb.connect(robot.url, options=options) as client:
        async with client.subscribe("/odm") as missing, client.subscribe("/odom") as offered:
            with anyio.fail_after(10):
                await offered.__anext__()
            await wait_until(
                lambda: any("/odm" in r.getMessage() for r in caplog.records),
                timeout=20.0,
                what="the warning",
            )
            await anyio.sleep(0.6)  # two more grace periods: still one warning
            assert missing.state == "pending"
    warnings = [r.getMessage() for r in caplog.records if r.levelno == logging.WARNING]
    about = [w for w in warnings if "does not offer" in w]
    assert about == [
        "no message on /odm after 0.3 s: the robot does not offer it; nearest: /odom"
    ], warnings


async def test_no_warning_when_the_topic_is_offered_or_the_warning_is_off(
    robot: DemoRobot, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, LOGGER)
    async with rmb.connect(robot.url, options=fox_options(unknown_topic_warning=0.2)) as client:
        async with client.subscribe("/odom") as sub:
            with anyio.fail_after(10):
                await sub.__anext__()
            await anyio.sleep(0.5)
    async with rmb.connect(robot.url, options=fox_options(unknown_topic_warning=None)) as client:
        async with client.subscribe("/odm"):
            await anyio.sleep(0.5)
    assert not [r for r in caplog.records if "does not offer" in r.getMessage()]
    with pytest.raises(ValueError, match="unknown_topic_warning"):
        rmb.ClientOptions(unknown_topic_warning=0)


async def test_async_for_over_subscribe_without_async_with_says_how(robot: DemoRobot) -> None:
    async with rmb.connect(robot.url, options=fox_options()) as client:
        with pytest.raises(TypeError, match=r"use `async with client\.subscribe\(\.\.\.\) as sub"):
            async for _ in client.subscribe("/odom"):  # type: ignore[attr-defined]
                pass
        with pytest.raises(TypeError, match="async with"):
            for _ in client.subscribe("/odom"):  # type: ignore[attr-defined]
                pass


def test_sync_client_waits_through_the_async_one(robot: DemoRobot) -> None:
    with rmb.connect_sync(robot.url, options=fox_options()) as client:
        assert client.wait_for_service("/set_led", timeout=10).type == SET_BOOL
        with pytest.raises(TimeoutError, match="nearest: /odom"):
            client.wait_for_topic("/odm", timeout=0.2)
        with pytest.raises(rmb.ParameterError, match="nope"):
            client.get_parameters(["nope"])


# -- rosbridge on the rclpy graph -----------------------------------------------------------


@pytest.mark.peer
async def test_rosbridge_misfits_are_one_class(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    async with rmb.connect(
        rosbridge.url, protocol="rosbridge", options=rosbridge_options()
    ) as client:
        with pytest.raises(rmb.MessageError) as pub:
            await client.publish("/rmb_contract_twist", TWIST, {"angular": {"w": 1}})
        assert_misfit(pub.value, "publish /rmb_contract_twist", "Twist", "angular.w")
        await client.wait_for_service("/set_flag", timeout=20)
        await wait_until(
            lambda: {s.name: s.type for s in client.services}["/set_flag"] != "",
            timeout=20.0,
            what="type",
        )
        with pytest.raises(rmb.MessageError) as call:
            await client.call_service("/set_flag", {"data": "yes please"})
        assert_misfit(call.value, "call_service /set_flag", "SetBool_Request", "data")
        with pytest.raises(rmb.MessageError) as goal:
            async with client.send_action_goal("/fibonacci", FIB, {"ordr": 3}):
                pass
        assert_misfit(goal.value, "send_action_goal /fibonacci", "Fibonacci_Goal", "ordr")
        answer = await client.call_service("/set_flag", {"data": True})
        assert answer.success is True


async def answer_a_typo_first(
    requests: rmb.ServiceRequests, caught: list[rmb.MessageError]
) -> None:
    """Reply to each request with a misspelt field (kept in ``caught``), then
    with the right one."""
    async for req in requests:
        with pytest.raises(rmb.MessageError) as bad:
            await req.reply({"success": True, "mesage": "typo"})
        caught.append(bad.value)
        await req.reply({"success": True, "message": "fixed"})


@pytest.mark.peer
async def test_rosbridge_serve_reply_misfit(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    name = "/rmb_contract_served"
    caught: list[rmb.MessageError] = []
    async with rmb.connect(
        rosbridge.url, protocol="rosbridge", options=rosbridge_options()
    ) as client:
        async with client.serve(name, SET_BOOL) as requests, anyio.create_task_group() as tg:
            tg.start_soon(answer_a_typo_first, requests, caught)
            request = {"cmd": "call", "service": name, "type": SET_BOOL, "args": {"data": True}}
            request["timeout"] = 10.0
            result = await anyio.to_thread.run_sync(lambda: ros_graph.command(request, timeout=30))
            tg.cancel_scope.cancel()
    assert result == {"response": {"success": True, "message": "fixed"}}
    assert len(caught) == 1
    assert_misfit(caught[0], f"reply to {name}", "SetBool_Response", "mesage")


@pytest.mark.peer
async def test_rosbridge_parameter_refusals(rosbridge: RosBridge, ros_graph: RosGraph) -> None:
    count, label = "/rmb_params:count", "/rmb_params:label"
    async with rmb.connect(
        rosbridge.url, protocol="rosbridge", options=rosbridge_options()
    ) as client:
        try:
            with pytest.raises(rmb.ParameterError) as refused:
                await client.set_parameters({count: "fast", label: "contract"})
            assert list(refused.value.reasons) == [count]
            assert refused.value.reasons[count] not in ("", "refused")  # the robot's own words
            assert refused.value.values == {count: 3, label: "contract"}
            assert ros_graph.command({"cmd": "param", "name": "count"}) == 3
            with pytest.raises(rmb.ParameterError) as missing:
                await client.get_parameters(["/rmb_params:cont", count])
            assert list(missing.value.reasons) == ["/rmb_params:cont"]
            hint = missing.value.reasons["/rmb_params:cont"]
            assert hint.startswith("not found; nearest: /rmb_params:count")
            assert missing.value.values == {count: 3}
        finally:
            await client.set_parameters({label: "demo"})


# -- Zenoh: zenoh-ros2-sdk nodes ------------------------------------------------------------


@pytest.mark.peer
async def test_zenoh_misfits_are_one_class(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, ros_share: Path
) -> None:
    sdk("service", "--name", "/sdk_set_bool")
    action = SdkNode(
        zenoh_router.locator, zenoh_domain, ros_share, "action", "--name", "/fibonacci"
    )
    try:
        async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as c:
            c.register_type(FIB, (ros_share / f"{FIB}.action").read_text(), encoding="ros2action")
            with pytest.raises(rmb.MessageError) as pub:
                await c.publish("/rmb_contract_int8", "std_msgs/msg/Int8", {"data": 300})
            assert_misfit(pub.value, "publish /rmb_contract_int8", "Int8", "data")
            assert "out of range" in pub.value.reason
            await c.wait_for_service("/sdk_set_bool", timeout=20)
            with pytest.raises(rmb.MessageError) as call:
                await c.call_service("/sdk_set_bool", {"data": True, "extra": 1})
            assert_misfit(call.value, "call_service /sdk_set_bool", "SetBool_Request", "extra")
            await c.wait_for_service("/fibonacci/_action/send_goal", timeout=20)
            with pytest.raises(rmb.MessageError) as goal:
                async with c.send_action_goal("/fibonacci", FIB, {"order": "three"}):
                    pass
            assert_misfit(
                goal.value, "send_action_goal /fibonacci", "SendGoal_Request", "goal.order"
            )
            answer = await c.call_service("/sdk_set_bool", {"data": True}, timeout=10)
            assert answer.success is True
    finally:
        action.stop()


@pytest.mark.peer
async def test_zenoh_serve_reply_misfit(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    name = "/rmb_contract_served"
    caught: list[rmb.MessageError] = []
    async with (
        rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client,
        client.serve(name, SET_BOOL) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(answer_a_typo_first, requests, caught)
        caller = await anyio.to_thread.run_sync(
            lambda: sdk(
                "client",
                "--name",
                name,
                "--type",
                SET_BOOL,
                "--requests",
                json.dumps([{"data": True}]),
            )
        )
        await wait_until(lambda: caller.done, timeout=40, what="the sdk's call")
        assert caller.records() == [{"response": {"success": True, "message": "fixed"}}]
        tg.cancel_scope.cancel()
    assert len(caught) == 1
    assert_misfit(caught[0], f"reply to {name}", "SetBool_Response", "mesage")


@pytest.mark.peer
async def test_zenoh_parameter_refusals(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("params")
    speed, readonly = "/sdk_params:speed", "/sdk_params:readonly"
    async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client:
        await client.wait_for_service("/sdk_params/set_parameters", timeout=20)
        with pytest.raises(rmb.ParameterError) as refused:
            await client.set_parameters({readonly: 1, speed: 2.5, "/nobody:x": 1})
        assert refused.value.reasons == {
            readonly: "read-only",  # the node's own SetParametersResult.reason
            "/nobody:x": "not found (no node /nobody)",
        }
        assert refused.value.values == {speed: 2.5}  # the accepted one is applied
        assert await client.get_parameters([speed]) == {speed: 2.5}
        with pytest.raises(rmb.ParameterError) as missing:
            await client.get_parameters(["/sdk_params:sped"])
        assert list(missing.value.reasons) == ["/sdk_params:sped"]
        hint = missing.value.reasons["/sdk_params:sped"]
        assert hint.startswith("not found; nearest: /sdk_params:speed")
