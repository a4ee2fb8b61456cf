"""Messages as classes, end to end: what a ROS developer writes with the
generated classes (``ros_mobile_bridge.interfaces``) against real peers, on
every transport where each call applies.

- Foxglove (the demo robot and the official Foxglove SDK server):
  ``subscribe(topic, Odometry)``, ``publish(topic, Twist(...))``,
  ``call_service(name, SetBool.Request(...))``, and the sync client;
- rosbridge (rosbridge_server_rs on a ROS 2 graph of rclpy nodes):
  subscriptions over JSON and ``cbor-raw``, publishing to a recording rclpy
  subscriber, services, the graph's ``test_msgs/action/Fibonacci`` (not
  bundled: its classes are made at run time from the bridge's
  descriptions) and serving a service to an rclpy caller;
- Zenoh (zenoh-ros2-sdk nodes through a real router): a talker, a listener,
  service servers, the Fibonacci action server and a service client.

Each received message, reply, feedback and result is checked to be an
instance of its exact class (never a dict where the definition is known)
with the peer's values. One test without a ROS peer: a channel whose
``std_msgs/msg/String`` has another definition than the bundled class.

Like the other protocol modules (conftest.py's ``LOOP_NEUTRAL``), each test
runs on one event loop, picked from its name (both with ``RMB_BOTH_LOOPS=1``):
the code under test is the same on both."""

from __future__ import annotations

import itertools
import json
import os
import struct
import zlib
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, TypeVar

import anyio
import numpy as np
import pytest
from foxglove import Schema

import ros_mobile_bridge as rmb
from _util import fast_options, take, wait_until, wait_until_sync, zenoh_options
from _util import rosbridge_options as rb_options
from peers.foxglove_sdk import SdkServer, decode, msgdef
from peers.rosbridge import RosBridge, RosGraph
from peers.zenoh_router import ZenohRouter
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.demo import DemoRobot
from ros_mobile_bridge.interfaces import RosMessage
from ros_mobile_bridge.interfaces.builtin_interfaces.msg import Time
from ros_mobile_bridge.interfaces.example_interfaces.srv import AddTwoInts
from ros_mobile_bridge.interfaces.geometry_msgs.msg import (
    Point,
    Pose,
    PoseWithCovariance,
    Quaternion,
    Twist,
    TwistWithCovariance,
    Vector3,
)
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.std_msgs.msg import Header, String
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool, Trigger

pytest_plugins = ["peers.ros_fixtures"]

F = TypeVar("F", bound=Callable[..., Any])
FIB = "test_msgs/action/Fibonacci"
ADD_TWO_INTS_SRV = "int64 a\nint64 b\n---\nint64 sum\n"
_unique = itertools.count()


def unique(name: str) -> str:
    return f"{name}_{os.getpid()}_{next(_unique)}"


def one_loop(test: F) -> F:
    """Run ``test`` on one event loop picked from its name (conftest.py's
    convention for protocol tests), on both with ``RMB_BOTH_LOOPS=1``."""
    if os.environ.get("RMB_BOTH_LOOPS", "") not in ("", "0"):
        loops = ["asyncio", "trio"]
    else:
        loops = [("asyncio", "trio")[zlib.crc32(test.__name__.encode()) % 2]]
    return pytest.mark.parametrize("anyio_backend", loops)(test)  # type: ignore[no-any-return]


def fibonacci(order: int) -> list[int]:
    """The sequence both Fibonacci servers end a goal of ``order`` with."""
    sequence = [0, 1]
    for _ in range(order):
        sequence.append(sequence[-1] + sequence[-2])
    return sequence


def assert_odometry(odom: Any) -> None:
    """``odom`` is an ``Odometry`` all the way down: every nested message an
    instance of its own class, the covariances numpy arrays."""
    assert type(odom) is Odometry
    assert type(odom.header) is Header and type(odom.header.stamp) is Time
    assert type(odom.pose) is PoseWithCovariance and type(odom.pose.pose) is Pose
    assert type(odom.pose.pose.position) is Point
    assert type(odom.pose.pose.orientation) is Quaternion
    assert type(odom.twist) is TwistWithCovariance and type(odom.twist.twist) is Twist
    assert type(odom.twist.twist.linear) is Vector3
    assert isinstance(odom.pose.covariance, np.ndarray) and odom.pose.covariance.shape == (36,)
    assert odom.header.frame_id == "odom" and odom.child_frame_id == "base_link"
    assert odom.header.stamp.sec > 0


def assert_sequence_message(message: Any, type_name: str) -> list[int]:
    """A Fibonacci feedback or result of the run-time class ``type_name``
    (``test_msgs`` is not bundled): its sequence."""
    assert issubclass(type(message), RosMessage), type(message)
    assert type(message).__ros_type__ == type_name
    assert isinstance(message.sequence, np.ndarray)
    assert message.to_dict().keys() == {"sequence"}
    return [int(x) for x in message.sequence]


# -- Foxglove: the demo robot -------------------------------------------------------


@one_loop
async def test_foxglove_odometry_twist_and_services_as_classes(robot: DemoRobot) -> None:
    """The demo robot's ``/odom`` arrives as ``Odometry``; a ``Twist``
    instance drives it (its odometry reports the applied velocity); its
    ``SetBool`` and ``Trigger`` services answer with response instances,
    for an instance request, a dict and no request at all."""
    before = len(robot.received_cmd_vel())
    async with rmb.connect(robot.url, options=fast_options()) as client:
        async with client.subscribe("/odom", Odometry, dispatch="latest") as odom:
            (first,) = await take(odom, 1)
            assert first.decode_error is None
            assert first.schema_name == "nav_msgs/msg/Odometry"
            assert_odometry(first.data)

            command = Twist(linear=Vector3(x=0.3), angular=Vector3(z=0.2))
            with anyio.fail_after(10):
                while True:  # the robot's watchdog wants commands at least every 0.5 s
                    await client.publish("/cmd_vel", command)
                    with anyio.move_on_after(0.1):
                        msg = await odom.__anext__()
                        twist = msg.data.twist.twist
                        if (twist.linear.x, twist.angular.z) == (0.3, 0.2):
                            break
            assert_odometry(msg.data)

        # the named-type form with an instance, and a dict holding an instance
        await client.publish("/cmd_vel", "geometry_msgs/msg/Twist", Twist(linear=Vector3(x=0.1)))
        await client.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"angular": Vector3(z=-0.4)})
        await wait_until(
            lambda: (
                [(c.linear_x, c.angular_z) for c in robot.received_cmd_vel()[before:]][-2:]
                == [(0.1, 0.0), (0.0, -0.4)]
            ),
            what=lambda: robot.received_cmd_vel()[before:][-3:],
        )

        on = await client.call_service("/set_led", SetBool.Request(data=True), timeout=5)
        assert type(on) is SetBool.Response
        assert on == SetBool.Response(success=True, message="led on")
        assert robot.led is True
        off = await client.call_service("/set_led", {"data": False}, timeout=5)
        assert type(off) is SetBool.Response
        assert (off.success, off.message) == (True, "led off")
        assert robot.parameters["led"] is False
        reset = await client.call_service("/reset_odometry", Trigger.Request(), timeout=5)
        assert type(reset) is Trigger.Response
        assert reset == Trigger.Response(success=True, message="odometry reset")
        bare = await client.call_service("/reset_odometry", timeout=5)
        assert type(bare) is Trigger.Response

        # a JSON channel with only a JSON Schema has no ROS definition: a dict
        async with client.subscribe("/status") as status:
            (report,) = await take(status, 1)
        assert type(report.data) is dict and "mode" in report.data


def test_sync_client_gives_instances(robot: DemoRobot) -> None:
    """``connect_sync``: the same classes through the blocking client."""
    before = len(robot.received_cmd_vel())
    with rmb.connect_sync(robot.url, options=fast_options(teardown_timeout=2.0)) as client:
        with client.subscribe("/odom", Odometry, timeout=5) as sub:
            msg = sub.get()
            assert msg.decode_error is None
            assert_odometry(msg.data)
            assert type(next(sub).data) is Odometry
        with client.subscribe("/pose", timeout=5) as pose:  # no class: still an instance
            assert type(pose.get().data.pose.position) is Point
        reply = client.call_service("/set_led", SetBool.Request(data=True), timeout=5)
        assert type(reply) is SetBool.Response
        assert reply == SetBool.Response(success=True, message="led on")
        client.publish("/cmd_vel", Twist(linear=Vector3(x=0.05)))
        wait_until_sync(
            lambda: any(c.linear_x == 0.05 for c in robot.received_cmd_vel()[before:]),
            what="the Twist at the robot",
        )


# -- Foxglove: the official SDK server --------------------------------------------------


@pytest.fixture
def foxglove() -> Iterator[SdkServer]:
    with SdkServer() as server:
        yield server


@one_loop
async def test_foxglove_a_string_instance_round_trips_through_the_sdk_server(
    foxglove: SdkServer,
) -> None:
    """A published ``String`` instance reaches the SDK server as the CDR
    rosbags decodes; the server sends those bytes back on a channel of its
    own, and a ``String`` subscription gets them as a ``String``."""
    echo = foxglove.channel("/echo", "std_msgs/msg/String")
    async with rmb.connect(foxglove.url, options=fast_options()) as client:
        async with client.subscribe("/echo", String) as sub:
            await wait_until(lambda: "/echo" in foxglove.subscribed(), what="the subscription")
            await client.publish("/note", String(data="ünïcode from a class"))
            await wait_until(lambda: foxglove.messages("/note"), what="the message at the server")
            (received,) = foxglove.messages("/note")
            assert (received.encoding, received.schema_name) == ("cdr", "std_msgs/msg/String")
            assert decode("std_msgs/msg/String", received.data).data == "ünïcode from a class"
            echo.log(received.data)
            (back,) = await take(sub, 1)
    assert type(back.data) is String
    assert back.data == String(data="ünïcode from a class")
    assert back.decode_error is None


def _string_with_extra(text: str, extra: int) -> bytes:
    """CDR of ``string data`` + ``int32 extra`` (little-endian)."""
    body = text.encode() + b"\x00"
    cdr = b"\x00\x01\x00\x00" + struct.pack("<I", len(body)) + body
    cdr += b"\x00" * (-(len(cdr) - 4) % 4)
    return cdr + struct.pack("<i", extra)


@one_loop
async def test_a_named_class_refuses_another_definition_of_its_type(
    foxglove: SdkServer,
) -> None:
    """The server's ``std_msgs/msg/String`` has an extra field: a
    subscription naming ``String`` gets each message raw, saying it is
    another definition; one naming no class gets an instance of a class made
    from the server's definition, with the extra field."""
    schema = Schema(
        name="std_msgs/msg/String", encoding="ros2msg", data=b"string data\nint32 extra\n"
    )
    other = foxglove.raw_channel("/other", encoding="cdr", schema=schema)
    async with rmb.connect(foxglove.url, options=fast_options()) as client:
        async with (
            client.subscribe("/other", String) as named,
            client.subscribe("/other") as unnamed,
        ):
            await wait_until(lambda: len(foxglove.subscribed()) >= 1, what="the subscription")
            await wait_until(lambda: named.state == unnamed.state == "active")
            other.log(_string_with_extra("hi", 7))
            (refused,) = await take(named, 1)
            (decoded,) = await take(unnamed, 1)
        assert named.stats.decode_failures == 1
        assert unnamed.stats.decode_failures == 0
    assert isinstance(refused.data, memoryview)
    assert bytes(refused.data) == _string_with_extra("hi", 7)
    assert refused.decode_error is not None
    assert "another definition" in refused.decode_error, refused.decode_error
    assert refused.schema_name == "std_msgs/msg/String"

    assert decoded.decode_error is None
    message: Any = decoded.data
    assert issubclass(type(message), RosMessage) and type(message) is not String
    assert type(message).__ros_type__ == "std_msgs/msg/String"
    assert type(message).__ros_hash__ != String.__ros_hash__
    assert (message.data, message.extra) == ("hi", 7)
    assert message.to_dict() == {"data": "hi", "extra": 7}


# -- rosbridge ------------------------------------------------------------------------


@one_loop
async def test_rosbridge_json_subscriptions_give_instances(rosbridge: RosBridge) -> None:
    """The graph's ``/chatter`` with its class named and ``/odom`` without
    one, over the default JSON: every message an instance."""
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        async with (
            client.subscribe("/chatter", String) as chatter,
            client.subscribe("/odom") as odom,
        ):
            said = await take(chatter, 5)
            moved = await take(odom, 10)
    for msg in said:
        assert msg.decode_error is None, msg.decode_error
        assert type(msg.data) is String
        assert msg.data.data.startswith("hello ")
    for msg in moved:
        assert msg.encoding == "json" and msg.decode_error is None
        assert_odometry(msg.data)
        assert msg.data.twist.twist.linear == Vector3(x=0.2)


@one_loop
async def test_rosbridge_cbor_raw_subscriptions_give_instances(rosbridge: RosBridge) -> None:
    """``cbor-raw`` (the bridge's CDR, decoded here): ``/odom`` with its
    class named and ``/chatter`` without one."""
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        async with (
            client.subscribe("/odom", Odometry, compression="cbor-raw") as odom,
            client.subscribe("/chatter", compression="cbor-raw") as chatter,
        ):
            moved = await take(odom, 3)
            said = await take(chatter, 2)
    for msg in moved:
        assert msg.decode_error is None, msg.decode_error
        assert_odometry(msg.data)
        assert msg.data.twist.twist.linear == Vector3(x=0.2)
    for msg in said:
        assert msg.decode_error is None, msg.decode_error
        assert type(msg.data) is String and msg.data.data.startswith("hello ")


async def _record(graph: RosGraph, topic: str, type_name: str) -> None:
    request = {"cmd": "record", "topic": topic, "type": type_name}
    await anyio.to_thread.run_sync(graph.command, request)


@one_loop
async def test_rosbridge_published_instances_reach_ros_and_come_back(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    """A ``String`` instance reaches an rclpy subscriber, and our own
    ``String`` subscription through the bridge (``cbor-raw``: JSON has a
    bug of its own, see the JSON subscription test); a Twist given as a dict
    holding a ``Vector3`` and as an instance under its type name reaches
    an rclpy Twist subscriber."""
    text, twist_topic = unique("/rmb_typed_text"), unique("/rmb_typed_twist")
    await _record(ros_graph, text, "std_msgs/msg/String")
    await _record(ros_graph, twist_topic, "geometry_msgs/msg/Twist")
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        async with client.subscribe(text, String, compression="cbor-raw") as sub:
            got: list[rmb.Message[String]] = []
            with anyio.fail_after(15):  # the first may beat the bridge's subscription
                for n in itertools.count():
                    await client.publish(text, String(data=f"typed {n}"))
                    with anyio.move_on_after(0.2):
                        got.append(await sub.__anext__())
                        break
        await client.publish(twist_topic, "geometry_msgs/msg/Twist", {"linear": Vector3(x=0.5)})
        await client.publish(twist_topic, "geometry_msgs/msg/Twist", Twist(angular=Vector3(z=-1.5)))
    (back,) = got
    assert back.decode_error is None, back.decode_error
    assert type(back.data) is String and back.data.data.startswith("typed ")
    heard = ros_graph.received(text)
    assert back.data.data in [m["data"] for m in heard]
    zero = {"x": 0.0, "y": 0.0, "z": 0.0}
    await wait_until(lambda: len(ros_graph.received(twist_topic)) >= 2, 10, "the Twists")
    assert ros_graph.received(twist_topic)[:2] == [
        {"linear": {"x": 0.5, "y": 0.0, "z": 0.0}, "angular": zero},
        {"linear": zero, "angular": {"x": 0.0, "y": 0.0, "z": -1.5}},
    ]


@one_loop
async def test_rosbridge_call_service_with_a_request_instance_right_after_connecting(
    rosbridge: RosBridge,
) -> None:
    """A ``SetBool.Request`` names its type: the response is a
    ``SetBool.Response`` even before discovery learnt the service's type."""
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        yes = await client.call_service("/set_flag", SetBool.Request(data=True), timeout=5)
    assert type(yes) is SetBool.Response
    assert yes == SetBool.Response(success=True, message="flag set to True")


@one_loop
async def test_rosbridge_call_service_gives_response_instances(rosbridge: RosBridge) -> None:
    """Once the graph's service type is known, a dict request gets an
    instance back too."""
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        await wait_until(
            lambda: (
                {s.name: s.type for s in client.services}.get("/set_flag") == "std_srvs/srv/SetBool"
            ),
            30,
            "the service's type",
        )
        yes = await client.call_service("/set_flag", SetBool.Request(data=True), timeout=5)
        no = await client.call_service("/set_flag", {"data": False}, timeout=5)
    assert type(yes) is SetBool.Response and type(no) is SetBool.Response
    assert yes == SetBool.Response(success=True, message="flag set to True")
    assert no == SetBool.Response(success=False, message="refused")


@one_loop
async def test_rosbridge_action_feedback_and_result_are_instances(rosbridge: RosBridge) -> None:
    """The graph's ``test_msgs/action/Fibonacci`` (not bundled): feedback
    and result are instances of classes made from the bridge's
    descriptions."""
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as client:
        async with client.send_action_goal("/fibonacci", FIB, {"order": 4}) as goal:
            with anyio.fail_after(10):
                await goal.accepted()
                feedback = [f async for f in goal.feedback]
                outcome = await goal.result()
    assert outcome.status == "succeeded"
    assert assert_sequence_message(outcome.result, f"{FIB}_Result") == fibonacci(4)
    assert feedback
    sequences = [assert_sequence_message(f, f"{FIB}_Feedback") for f in feedback]
    assert all(s == fibonacci(4)[: len(s)] for s in sequences)
    assert len({type(f) for f in feedback}) == 1  # one class for the type, not one per message


@one_loop
async def test_rosbridge_serve_with_the_service_class(
    rosbridge: RosBridge, ros_graph: RosGraph
) -> None:
    """``serve(name, SetBool)``: an rclpy caller's request arrives as a
    ``SetBool.Request`` and our ``SetBool.Response`` reaches it; a second
    client calling through the bridge gets a ``SetBool.Response`` (its
    request arrives as a ``SetBool.Request`` too).
    (``example_interfaces`` is not in the ROS peer environment, so the
    bridge cannot serve AddTwoInts; the Zenoh test serves it.)"""
    name = unique("/rmb_typed_served")
    seen: list[Any] = []

    async def answer(requests: rmb.ServiceRequests) -> None:
        async for req in requests:
            seen.append(req.args)
            await req.reply(SetBool.Response(success=req.args.data, message=f"got {req.args.data}"))

    async def ros_call(data: bool) -> Any:
        request = {
            "cmd": "call",
            "service": name,
            "type": "std_srvs/srv/SetBool",
            "args": {"data": data},
        }
        return await anyio.to_thread.run_sync(lambda: ros_graph.command(request, timeout=15))

    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as server,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=rb_options()) as caller,
    ):
        async with server.serve(name, SetBool) as requests, anyio.create_task_group() as tg:
            tg.start_soon(answer, requests)
            first = await ros_call(True)
            second = await ros_call(False)
            await wait_until(
                lambda: (
                    {s.name: s.type for s in caller.services}.get(name) == "std_srvs/srv/SetBool"
                ),
                30,
                "the served service's type at the second client",
            )
            third = await caller.call_service(name, SetBool.Request(data=True), timeout=5)
            tg.cancel_scope.cancel()
    assert first == {"response": {"success": True, "message": "got True"}}
    assert second == {"response": {"success": False, "message": "got False"}}
    assert type(third) is SetBool.Response
    assert third == SetBool.Response(success=True, message="got True")
    assert [type(a) for a in seen] == [SetBool.Request] * 3
    assert seen == [
        SetBool.Request(data=True),
        SetBool.Request(data=False),
        SetBool.Request(data=True),
    ]


# -- Zenoh ----------------------------------------------------------------------------


@pytest.fixture
def sdk_share(ros_share: Path, tmp_path: Path) -> Path:
    """The official interface files plus ``example_interfaces/srv/AddTwoInts.srv``
    (not in the peer environment), for sdk nodes that speak AddTwoInts."""
    tree = tmp_path / "share"
    tree.mkdir()
    for entry in ros_share.iterdir():
        (tree / entry.name).symlink_to(entry)
    srv_dir = tree / "example_interfaces" / "srv"
    srv_dir.mkdir(parents=True)
    (srv_dir / "AddTwoInts.srv").write_text(ADD_TWO_INTS_SRV)
    return tree


async def _zenoh_offers(client: rmb.Client, kind: str, name: str) -> None:
    """Wait until the client's graph shows the sdk's ``kind`` ("topic" or
    "service") ``name``."""

    def offered() -> bool:
        things = client.topics if kind == "topic" else client.services
        return any(t.name == name for t in things)

    await wait_until(offered, 15.0, f"the sdk's {kind} {name}")


@one_loop
async def test_zenoh_subscriptions_give_instances(
    sdk: Callable[..., SdkNode], zenoh_router: ZenohRouter, zenoh_domain: int
) -> None:
    """An sdk talker's ``String`` with the class named and without a class."""
    await anyio.to_thread.run_sync(lambda: sdk("talker", "--rate", "50"))
    async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client:
        await _zenoh_offers(client, "topic", "/chatter")
        async with (
            client.subscribe("/chatter", String) as named,
            client.subscribe("/chatter") as unnamed,
        ):
            got = await take(named, 3) + await take(unnamed, 3)
    for msg in got:
        assert msg.decode_error is None
        assert type(msg.data) is String
        assert msg.data.data.startswith("hello ")
    numbers = [int(m.data.data.split()[1]) for m in got[:3]]
    assert numbers == list(range(numbers[0], numbers[0] + 3))


@one_loop
async def test_zenoh_published_instances_reach_the_sdk_listener(
    sdk: Callable[..., SdkNode], zenoh_router: ZenohRouter, zenoh_domain: int
) -> None:
    listener = await anyio.to_thread.run_sync(
        lambda: sdk("listener", "--topic", "/typed", "--type", "std_msgs/msg/String")
    )
    async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client:
        with anyio.fail_after(15):  # a sample put before the router routes it is lost
            while not listener.messages():
                await client.publish("/typed", String(data="probe"))
                with anyio.move_on_after(0.2):
                    while not listener.messages():
                        await anyio.sleep(0.02)
        await client.publish("/typed", String(data="from a class"))
        await client.publish("/typed", "std_msgs/msg/String", String(data="named, an instance"))
        await client.publish("/typed", "std_msgs/msg/String", {"data": "a dict"})

        def ours() -> list[str]:
            return [m["data"] for m in listener.messages() if m["data"] != "probe"]

        await wait_until(lambda: len(ours()) >= 3, 15.0, "the messages at the listener")
    assert ours() == ["from a class", "named, an instance", "a dict"]


@one_loop
async def test_zenoh_call_service_gives_response_instances(
    sdk: Callable[..., SdkNode], zenoh_router: ZenohRouter, zenoh_domain: int, sdk_share: Path
) -> None:
    """The sdk's SetBool and AddTwoInts servers: instance and dict requests
    both get response instances."""
    await anyio.to_thread.run_sync(lambda: sdk("service", "--name", "/sdk_set_bool"))
    await anyio.to_thread.run_sync(
        lambda: sdk("add_two_ints", "--name", "/sdk_add", share=sdk_share)
    )
    async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client:
        await _zenoh_offers(client, "service", "/sdk_set_bool")
        await _zenoh_offers(client, "service", "/sdk_add")
        yes = await client.call_service("/sdk_set_bool", SetBool.Request(data=True), timeout=5)
        no = await client.call_service("/sdk_set_bool", {"data": False}, timeout=5)
        total = await client.call_service("/sdk_add", AddTwoInts.Request(a=-5, b=2**40), timeout=5)
        small = await client.call_service("/sdk_add", {"a": 2, "b": 3}, timeout=5)
    assert type(yes) is SetBool.Response and type(no) is SetBool.Response
    assert yes == SetBool.Response(success=True, message="set to True")
    assert no == SetBool.Response(success=False, message="set to False")
    assert type(total) is AddTwoInts.Response and type(small) is AddTwoInts.Response
    assert (total.sum, small.sum) == (2**40 - 5, 5)


@one_loop
async def test_zenoh_action_feedback_and_result_are_instances(
    sdk: Callable[..., SdkNode], zenoh_router: ZenohRouter, zenoh_domain: int, ros_share: Path
) -> None:
    """The sdk's ``test_msgs/action/Fibonacci`` server, its type registered
    from the official ``.action`` file: feedback and result are instances
    of the classes made from it."""
    await anyio.to_thread.run_sync(lambda: sdk("action", "--name", "/fibonacci", "--step", "0.05"))
    async with rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client:
        client.register_type(FIB, (ros_share / f"{FIB}.action").read_text(), encoding="ros2action")
        await _zenoh_offers(client, "service", "/fibonacci/_action/cancel_goal")
        async with client.send_action_goal("/fibonacci", FIB, {"order": 6}) as goal:
            with anyio.fail_after(10):
                await goal.accepted()
                feedback = [f async for f in goal.feedback]
                outcome = await goal.result()
    assert outcome.status == "succeeded"
    assert assert_sequence_message(outcome.result, f"{FIB}_Result") == fibonacci(6)
    assert feedback
    sequences = [assert_sequence_message(f, f"{FIB}_Feedback") for f in feedback]
    assert all(s == fibonacci(6)[: len(s)] for s in sequences)


@one_loop
async def test_zenoh_serve_add_two_ints_with_its_class(
    sdk: Callable[..., SdkNode], zenoh_router: ZenohRouter, zenoh_domain: int, sdk_share: Path
) -> None:
    """``serve(name, AddTwoInts)`` with no ``register_type`` (the class is
    bundled): the sdk client's calls arrive as ``AddTwoInts.Request`` and it
    gets the sums our ``AddTwoInts.Response`` carries."""
    seen: list[Any] = []

    async def add(requests: rmb.ServiceRequests) -> None:
        async for req in requests:
            seen.append(req.args)
            await req.reply(AddTwoInts.Response(sum=req.args.a + req.args.b))

    calls = [{"a": 1, "b": 2}, {"a": -5, "b": 2**40}]
    async with (
        rmb.connect(zenoh_router.locator, options=zenoh_options(zenoh_domain)) as client,
        client.serve("/rmb_add", AddTwoInts) as requests,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(add, requests)
        caller = await anyio.to_thread.run_sync(
            lambda: sdk(
                "client",
                "--name",
                "/rmb_add",
                "--type",
                "example_interfaces/srv/AddTwoInts",
                "--requests",
                json.dumps(calls),
                share=sdk_share,
            )
        )
        await wait_until(lambda: caller.done, 30.0, "the sdk's calls")
        tg.cancel_scope.cancel()
    assert caller.records() == [{"response": {"sum": 3}}, {"response": {"sum": 2**40 - 5}}]
    assert [type(a) for a in seen] == [AddTwoInts.Request] * 2
    assert seen == [AddTwoInts.Request(a=1, b=2), AddTwoInts.Request(a=-5, b=2**40)]


def test_the_bundled_string_schema_is_what_the_sdk_server_advertises() -> None:
    """(The mismatch test's premise: the bundled ``String`` is the official
    one, so only the extra field makes that channel's type differ.)"""
    assert msgdef("std_msgs/msg/String").decode().split() == ["string", "data"]
    assert String.__ros_fields__ == (("data", "string"),)
