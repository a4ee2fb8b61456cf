"""The Client against the official Foxglove SDK server (foxglove-sdk), in-process.

Every test runs on asyncio and trio. The server is a real peer: what it
receives is what the library put on the wire."""

from __future__ import annotations

import json
import struct
import threading
import time
from collections.abc import Iterator
from typing import Any

import anyio
import numpy as np
import pytest
from foxglove import Schema

import ros_mobile_bridge as rmb
from _util import fast_options as options
from _util import wait_until
from peers.foxglove_sdk import SdkServer, cdr, decode, image_msg, ros2_service, string_msg
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool, Trigger


@pytest.fixture
def server() -> Iterator[SdkServer]:
    with SdkServer(parameters={"max_speed": 1.5, "name": "robot", "enabled": True}) as srv:
        yield srv


# -- connection and discovery -------------------------------------------------


async def test_connect_negotiates_newest_subprotocol_and_reads_server_info(
    server: SdkServer,
) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        assert robot.protocol == "foxglove-ws"
        assert robot.status == "connected"
        assert robot.server_info.subprotocol == "foxglove.sdk.v1.1"
        assert "clientPublish" in robot.server_info.capabilities
        assert set(robot.server_info.supported_encodings) == {"json", "cdr"}
    assert robot.status == "closed"


async def test_server_without_channels_connects_without_waiting_for_advertise(
    server: SdkServer,
) -> None:
    with anyio.fail_after(2):
        async with rmb.connect(server.url, options=options()) as robot:
            assert robot.topics == []
            assert robot.services == []


async def test_topic_list_follows_runtime_advertise_and_unadvertise(server: SdkServer) -> None:
    first = server.channel("/odom", "nav_msgs/msg/Odometry")
    async with rmb.connect(server.url, options=options()) as robot:
        assert [t.name for t in robot.topics] == ["/odom"]
        assert robot.topics[0].schema_name == "nav_msgs/msg/Odometry"
        assert robot.topics[0].encoding == "cdr"
        seen: list[list[str]] = []
        async with anyio.create_task_group() as tg:

            async def watch() -> None:
                async for topics in robot.watch_topics():
                    seen.append([t.name for t in topics])
                    if len(seen) == 3:
                        return

            tg.start_soon(watch)
            await wait_until(lambda: len(seen) == 1, what="initial topic list")
            second = server.channel("/battery", "sensor_msgs/msg/BatteryState")
            await wait_until(lambda: len(seen) == 2, what="advertise")
            first.close()
        assert seen == [["/odom"], ["/battery", "/odom"], ["/battery"]]
        second.close()


async def test_service_list_and_watch(server: SdkServer) -> None:
    server.server.add_services(
        [
            ros2_service(
                "/a", "std_srvs/srv/Trigger", "", "bool success\nstring message", lambda r: b""
            )
        ]
    )
    async with rmb.connect(server.url, options=options()) as robot:
        await wait_until(lambda: [s.name for s in robot.services] == ["/a"], what="service list")
        assert robot.services[0].type == "std_srvs/srv/Trigger"
        watcher = robot.watch_services()
        assert [s.name for s in await watcher.__anext__()] == ["/a"]
        server.server.remove_services(["/a"])
        with anyio.fail_after(5):
            assert await watcher.__anext__() == []


# -- subscribing ---------------------------------------------------------------


async def test_subscribe_cdr_topic_decodes_messages(server: SdkServer) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: sub.state == "active")
            await wait_until(lambda: "/chatter" in server.subscribed())
            for i in range(3):
                chatter.log(string_msg(f"hello {i}"), log_time=1000 + i)
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg)
                    if len(got) == 3:
                        break
    assert [m.data.data for m in got] == ["hello 0", "hello 1", "hello 2"]
    assert [m.log_time_ns for m in got] == [1000, 1001, 1002]
    assert all(m.topic == "/chatter" and m.encoding == "cdr" for m in got)
    assert got[0].schema_name == "std_msgs/msg/String"
    assert got[0].byte_size == len(string_msg("hello 0"))
    assert sub.stats.delivered == 3 and sub.stats.decode_failures == 0


async def test_subscribe_json_topic(server: SdkServer) -> None:
    schema = Schema(name="demo/Status", encoding="jsonschema", data=b'{"type":"object"}')
    status = server.raw_channel("/status", encoding="json", schema=schema)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/status") as sub:
            await wait_until(lambda: "/status" in server.subscribed())
            status.log(json.dumps({"mode": "auto", "speed": 0.5}).encode())
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.encoding == "json"
    assert msg.data == {"mode": "auto", "speed": 0.5}


async def test_image_data_is_a_numpy_array(server: SdkServer) -> None:

    cam = server.channel("/camera", "sensor_msgs/msg/Image")
    pixels = np.arange(640 * 480 * 3, dtype=np.uint64).astype(np.uint8)
    payload = image_msg(pixels=pixels, stamp=(1, 2), frame_id="cam")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/camera") as sub:
            await wait_until(lambda: "/camera" in server.subscribed())
            cam.log(payload)
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.data.width == 640 and msg.data.encoding == "rgb8"
    assert isinstance(msg.data.data, np.ndarray)
    assert np.array_equal(msg.data.data, pixels)


async def test_topic_advertised_later_goes_from_pending_to_active(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/late") as sub:
            assert sub.state == "pending"
            late = server.channel("/late", "std_msgs/msg/String")
            with anyio.fail_after(5):
                await sub.wait_active()
            await wait_until(lambda: "/late" in server.subscribed())
            late.log(string_msg("finally"))
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.data.data == "finally"


async def test_unadvertised_topic_goes_pending_and_readvertised_topic_resumes(
    server: SdkServer,
) -> None:
    first = server.channel("/flip", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/flip", buffer=16) as sub:
            await wait_until(lambda: "/flip" in server.subscribed())
            first.log(string_msg("before"))
            await wait_until(lambda: sub.stats.received == 1, what="first frame")
            first.close()
            await wait_until(lambda: sub.state == "pending", what="pending after unadvertise")
            # re-advertised under a new id and a different type
            second = server.channel("/flip", "std_msgs/msg/Int32")
            await wait_until(lambda: sub.state == "active", what="active after re-advertise")
            await wait_until(lambda: server.subscribed().count("/flip") == 2)
            second.log(cdr("std_msgs/msg/Int32", data=42))
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg)
                    if len(got) == 2:
                        break
    # the frame queued before the unadvertise decodes with its own channel's schema
    assert got[0].schema_name == "std_msgs/msg/String" and got[0].data.to_dict() == {
        "data": "before"
    }
    assert got[1].schema_name == "std_msgs/msg/Int32" and got[1].data.to_dict() == {"data": 42}


async def test_undecodable_payload_and_bad_schema_are_delivered_raw(server: SdkServer) -> None:
    good = server.channel("/good", "std_msgs/msg/String")
    bad_schema = server.raw_channel(
        "/bad_schema",
        encoding="cdr",
        schema=Schema(name="x/msg/Y", encoding="ros2msg", data=b"this is { not a msg"),
    )
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/good") as sub, robot.subscribe("/bad_schema") as sub2:
            await wait_until(lambda: {"/good", "/bad_schema"} <= set(server.subscribed()))
            good.log(b"\x00\x01\x00\x00\xff\xff\xff\x7f")  # string length far past the end
            bad_schema.log(b"\x00\x01\x00\x00abcd")
            good.log(string_msg("still fine"))
            with anyio.fail_after(5):
                broken = await sub.__anext__()
                fine = await sub.__anext__()
                raw = await sub2.__anext__()
    assert isinstance(broken.data, memoryview) and broken.decode_error
    assert bytes(broken.data) == b"\x00\x01\x00\x00\xff\xff\xff\x7f"
    assert fine.data.to_dict() == {"data": "still fine"}
    assert isinstance(raw.data, memoryview) and bytes(raw.data) == b"\x00\x01\x00\x00abcd"
    assert sub.stats.decode_failures == 1


async def test_max_hz_cap_drops_before_decoding_and_delivers_the_trailing_message(
    server: SdkServer,
) -> None:
    chatter = server.channel("/fast", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/fast", max_hz=2) as sub:
            await wait_until(lambda: "/fast" in server.subscribed())
            for i in range(50):
                chatter.log(string_msg(f"m{i}"))
            await wait_until(lambda: sub.stats.received == 50, what="all 50 frames routed")
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg.data.data)
                    if msg.data.data == "m49":
                        break
    # a burst inside one window: the first frame passes, the newest is the trailing one
    assert got == ["m0", "m49"]
    assert sub.stats.dropped_throttle == 48
    assert sub.stats.delivered == 2


async def test_dispatch_latest_conflates_for_a_slow_consumer(server: SdkServer) -> None:
    chatter = server.channel("/c", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/c", dispatch="latest") as sub:
            await wait_until(lambda: "/c" in server.subscribed())
            for i in range(20):
                chatter.log(string_msg(f"m{i}"))
            await wait_until(lambda: sub.stats.received == 20)
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.data.data == "m19"
    assert sub.stats.dropped_conflated == 19 and sub.stats.delivered == 1


async def test_overflow_drops_the_oldest_undecoded(server: SdkServer) -> None:
    chatter = server.channel("/o", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/o", buffer=4) as sub:
            await wait_until(lambda: "/o" in server.subscribed())
            for i in range(10):
                chatter.log(string_msg(f"m{i}"))
            await wait_until(lambda: sub.stats.received == 10)
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg.data.data)
                    if len(got) == 4:
                        break
    assert got == ["m6", "m7", "m8", "m9"]
    assert sub.stats.dropped_overflow == 6 and sub.stats.delivered == 4


async def test_leaving_the_block_unsubscribes_at_the_server(server: SdkServer) -> None:
    server.channel("/u", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/u"):
            await wait_until(lambda: "/u" in server.subscribed())
        await wait_until(
            lambda: "/u" in server.recorder.unsubscribed, what="server-side unsubscribe"
        )


# -- publishing ------------------------------------------------------------------


async def test_publish_cdr_reaches_the_server_exactly(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        await robot.publish(
            "/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.25}, "angular": {"z": -1.0}}
        )
        await wait_until(lambda: server.messages("/cmd_vel"))
        first = server.messages("/cmd_vel")[0]
    assert server.recorder.advertised[0][1:] == ("/cmd_vel", "cdr", "geometry_msgs/msg/Twist")
    assert first.encoding == "cdr"
    twist = decode("geometry_msgs/msg/Twist", first.data)
    assert (twist.linear.x, twist.linear.y, twist.angular.z) == (0.25, 0.0, -1.0)


async def test_publish_json_when_the_server_only_accepts_json() -> None:
    with SdkServer(supported_encodings=["json"]) as srv:
        async with rmb.connect(srv.url, options=options(zero_twist_on_exit=False)) as robot:
            await robot.publish("/note", "std_msgs/msg/String", {"data": "hi"})
            await wait_until(lambda: srv.messages("/note"))
        msg = srv.messages("/note")[0]
    assert msg.encoding == "json"
    assert json.loads(msg.data) == {"data": "hi"}


async def test_advertise_ahead_and_unadvertise(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await robot.advertise("/log", "std_msgs/msg/String")
        await wait_until(lambda: server.recorder.advertised)
        await robot.publish("/log", "std_msgs/msg/String", {"data": "x"})
        await wait_until(lambda: server.messages("/log"))
        await robot.unadvertise("/log")
        await wait_until(lambda: server.recorder.unadvertised)
    assert len(server.recorder.advertised) == 1


async def test_publish_rejects_bad_arguments_at_once(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        with pytest.raises(ValueError, match="absolute ROS name"):
            await robot.publish("cmd_vel", "geometry_msgs/msg/Twist", {})
        with pytest.raises(ValueError, match="ROS type"):
            await robot.publish("/cmd_vel", "not a type", {})
        with pytest.raises(TypeError):
            await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", [1, 2])  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="priority"):
            await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {}, priority="urgent")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match=r"'linear\.w': unknown field"):
            await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"w": 1.0}})
        with pytest.raises(ValueError, match="max_hz"):
            robot.subscribe("/x", max_hz=0)
        with pytest.raises(ValueError, match="dispatch"):
            robot.subscribe("/x", dispatch="sometimes")  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="timeout"):
            await robot.call_service("/x", {}, timeout=0)


# -- services ---------------------------------------------------------------------


def setbool_handler(calls: list[bytes]) -> Any:
    def handle(req: Any) -> bytes:
        calls.append(bytes(req.payload))
        flag = bool(req.payload[4])  # CDR header, then the one bool
        return cdr_setbool_response(True, "on" if flag else "off")

    return handle


def cdr_setbool_response(success: bool, message: str) -> bytes:
    body = message.encode() + b"\x00"
    return (
        b"\x00\x01\x00\x00"
        + bytes([success])
        + b"\x00\x00\x00"
        + struct.pack("<I", len(body))
        + body
    )


async def test_call_service_sends_cdr_and_decodes_the_response() -> None:
    calls: list[bytes] = []
    svc = ros2_service(
        "/set_flag",
        "std_srvs/srv/SetBool",
        "bool data",
        "bool success\nstring message",
        setbool_handler(calls),
    )
    with SdkServer(services=[svc]) as srv:
        latencies: list[float] = []
        async with rmb.connect(srv.url, options=options(on_latency=latencies.append)) as robot:
            reply = await robot.call_service("/set_flag", {"data": True}, timeout=5)
            reply2 = await robot.call_service("/set_flag", {"data": False}, timeout=5)
    assert reply == SetBool.Response(success=True, message="on")
    assert reply2 == SetBool.Response(success=True, message="off")
    assert calls[0] == b"\x00\x01\x00\x00\x01"
    assert len(latencies) == 2 and all(x >= 0 for x in latencies)


async def test_service_failure_raises_service_error_with_the_server_text() -> None:
    def fail(req: Any) -> bytes:
        raise RuntimeError("the flag is stuck")

    svc = ros2_service(
        "/stuck", "std_srvs/srv/SetBool", "bool data", "bool success\nstring message", fail
    )
    with SdkServer(services=[svc]) as srv:
        async with rmb.connect(srv.url, options=options()) as robot:
            with pytest.raises(rmb.ServiceError, match="the flag is stuck") as info:
                await robot.call_service("/stuck", {"data": True}, timeout=5)
            assert info.value.service == "/stuck"
            with pytest.raises(rmb.ServiceError, match="does not advertise"):
                await robot.call_service("/nope", {}, timeout=5)


async def test_silent_service_raises_service_timeout_at_the_deadline() -> None:
    release = threading.Event()

    def silent(req: Any) -> bytes:
        release.wait(10)
        return cdr_setbool_response(True, "late")

    svc = ros2_service(
        "/slow", "std_srvs/srv/SetBool", "bool data", "bool success\nstring message", silent
    )
    with SdkServer(services=[svc]) as srv:
        try:
            async with rmb.connect(srv.url, options=options()) as robot:
                start = time.monotonic()
                with pytest.raises(rmb.ServiceTimeout) as info:
                    await robot.call_service("/slow", {"data": True}, timeout=0.3)
                assert isinstance(info.value, TimeoutError)
                assert 0.25 <= time.monotonic() - start < 3
        finally:
            release.set()


async def test_schemaless_service_gets_the_bare_cdr_header() -> None:
    calls: list[bytes] = []

    def handle(req: Any) -> bytes:
        calls.append(bytes(req.payload))
        return b"\x00\x01\x00\x00\x01\x00\x00\x00" + struct.pack("<I", 3) + b"ok\x00"

    svc = ros2_service("/trigger", "std_srvs/srv/Trigger", None, None, handle)
    with SdkServer(services=[svc]) as srv:
        async with rmb.connect(srv.url, options=options()) as robot:
            reply = await robot.call_service("/trigger", timeout=5)
    assert calls == [b"\x00\x01\x00\x00"]
    # std_srvs/srv/Trigger is bundled, so the response decodes without a server schema
    assert reply == Trigger.Response(success=True, message="ok")


# -- parameters ---------------------------------------------------------------------


async def test_get_set_and_list_parameters(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        assert await robot.get_parameters(["max_speed"]) == {"max_speed": 1.5}
        assert await robot.list_parameters() == {"max_speed": 1.5, "name": "robot", "enabled": True}
        result = await robot.set_parameters({"max_speed": 2.0, "name": "rover"})
        assert result == {"max_speed": 2.0, "name": "rover"}
        assert isinstance(result["max_speed"], float)
        assert await robot.get_parameters(["max_speed", "name"]) == {
            "max_speed": 2.0,
            "name": "rover",
        }


async def test_parameter_updates_arrive_while_watching(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.watch_parameters(["max_speed"]) as updates:
            await wait_until(lambda: "max_speed" in server.recorder.param_subscribed)
            server.publish_parameters({"max_speed": 3.5})
            with anyio.fail_after(5):
                first = await updates.__anext__()
    assert first == {"max_speed": 3.5}


# -- the zero Twist on teardown ----------------------------------------------------------


def last_twist(srv: SdkServer, topic: str = "/cmd_vel") -> Any:
    return decode("geometry_msgs/msg/Twist", srv.messages(topic)[-1].data)


async def test_zero_twist_on_normal_exit_arrives_last(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        for i in range(5):
            await robot.publish(
                "/cmd_vel",
                "geometry_msgs/msg/Twist",
                {"linear": {"x": 0.1 * (i + 1)}},
                priority="control",
            )
        await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.9}})
    await wait_until(lambda: server.messages("/cmd_vel"))
    twist = last_twist(server)
    assert (twist.linear.x, twist.angular.z) == (0.0, 0.0)
    assert all(
        decode("geometry_msgs/msg/Twist", m.data).linear.x > 0
        for m in server.messages("/cmd_vel")[:-1]
    )


async def test_zero_twist_on_exception_in_the_body(server: SdkServer) -> None:
    with pytest.raises(KeyError, match="boom"):
        async with rmb.connect(server.url, options=options()) as robot:
            await robot.publish(
                "/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.5}}, priority="control"
            )
            raise KeyError("boom")
    await wait_until(lambda: len(server.messages("/cmd_vel")) >= 2)
    assert last_twist(server).linear.x == 0.0


async def test_zero_twist_on_cancellation_of_the_enclosing_scope(server: SdkServer) -> None:
    published = anyio.Event()
    with anyio.CancelScope() as scope:
        async with rmb.connect(server.url, options=options()) as robot:
            await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.5}})
            published.set()
            scope.cancel()
            await anyio.sleep_forever()
    assert scope.cancelled_caught
    await wait_until(lambda: len(server.messages("/cmd_vel")) >= 2)
    assert last_twist(server).linear.x == 0.0


async def test_stop_topics_and_twist_stamped_get_a_zero(server: SdkServer) -> None:
    opts = options(stop_topics=("/emergency_cmd",))
    async with rmb.connect(server.url, options=opts) as robot:
        await robot.publish(
            "/cmd_vel_stamped", "geometry_msgs/msg/TwistStamped", {"twist": {"linear": {"x": 0.3}}}
        )
    await wait_until(
        lambda: server.messages("/emergency_cmd") and len(server.messages("/cmd_vel_stamped")) == 2
    )
    stamped = decode("geometry_msgs/msg/TwistStamped", server.messages("/cmd_vel_stamped")[-1].data)
    assert stamped.twist.linear.x == 0.0 and stamped.header.stamp.sec > 0
    assert (
        decode("geometry_msgs/msg/Twist", server.messages("/emergency_cmd")[-1].data).linear.x
        == 0.0
    )


async def test_control_burst_coalesces_to_the_newest_value(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")
        # queued without yielding: the writer sees only the newest control value
        for i in range(10):
            robot._conn.outbound.outbox.put_control(
                "/cmd_vel",
                robot._conn.adapter.encode_publish("/cmd_vel", {"linear": {"x": float(i)}}),
            )
        await wait_until(lambda: server.messages("/cmd_vel"))
        await anyio.sleep(0.2)
    xs = [decode("geometry_msgs/msg/Twist", m.data).linear.x for m in server.messages("/cmd_vel")]
    assert xs == [9.0]


async def test_publish_zero_twist_helper(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await robot.publish_zero_twist()
        await wait_until(lambda: server.messages("/cmd_vel"))
    assert last_twist(server).linear.x == 0.0
    assert len(server.messages("/cmd_vel")) == 1


# -- schemas ------------------------------------------------------------------------------


async def test_schema_template_fills_fixed_arrays(server: SdkServer) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        odom = robot.schema_template("nav_msgs/msg/Odometry")
        assert len(odom["pose"]["covariance"]) == 36
        assert odom["twist"]["twist"]["linear"] == {"x": 0.0, "y": 0.0, "z": 0.0}
        fields = robot.schema_definition("geometry_msgs/Twist")
        assert [f.name for f in fields] == ["linear", "angular"]
