"""The Client against the deprecated pure-Python Foxglove server
(``foxglove-websocket``, ``peers.foxglove_legacy``): the old subprotocol
``foxglove.websocket.v1``, ids from 0, inline schemas, fragmented binary
messages. Plus why the client offers all three subprotocols: the current
official server (Foxglove SDK) refuses the legacy one outright.

Every test runs on asyncio and trio."""

from __future__ import annotations

import json
import logging
import struct
from collections.abc import Iterator
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import fast_options as options
from _util import wait_until
from peers.foxglove_legacy import LegacyServer
from peers.foxglove_sdk import SdkServer, decode, string_msg
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool, Trigger
from ros_mobile_bridge.transport import HandshakeRejected, connect_websocket

# Marked here, not only by conftest: anyio's plugin rebuilds items it marks
# late and would drop the parametrization below.


LOGGER = "ros_mobile_bridge"
LEGACY = "foxglove.websocket.v1"


@pytest.fixture
def server() -> Iterator[LegacyServer]:
    with LegacyServer() as srv:
        yield srv
        # nothing the client sent made the server fail
        if not srv.errors_expected:
            assert srv.errors() == []


def add_chatter(srv: LegacyServer, topic: str = "/chatter") -> int:
    """A CDR std_msgs/msg/String channel the old way: inline ros2msg text and
    no ``schemaEncoding`` field."""
    return srv.add_channel(
        topic, encoding="cdr", schema_name="std_msgs/msg/String", schema="string data"
    )


def add_status(srv: LegacyServer) -> int:
    schema = {"type": "object", "properties": {"mode": {"type": "string"}}}
    return srv.add_channel(
        "/status",
        encoding="json",
        schema_name="demo/Status",
        schema=json.dumps(schema),
        schema_encoding="jsonschema",
    )


def cdr_string(text: str) -> bytes:
    body = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(body)) + body


def setbool_handler(encoding: str, payload: bytes) -> bytes:
    assert encoding == "cdr"
    return cdr_bool_and_string(True, "on" if payload[4] else "off")


def cdr_bool_and_string(flag: bool, text: str) -> bytes:
    body = text.encode() + b"\x00"
    return (
        b"\x00\x01\x00\x00" + bytes([flag]) + b"\x00\x00\x00" + struct.pack("<I", len(body)) + body
    )


SETBOOL = {
    "name": "/set_flag",
    "type": "std_srvs/srv/SetBool",
    "request": {
        "encoding": "cdr",
        "schemaName": "std_srvs/srv/SetBool_Request",
        "schemaEncoding": "ros2msg",
        "schema": "bool data",
    },
    "response": {
        "encoding": "cdr",
        "schemaName": "std_srvs/srv/SetBool_Response",
        "schemaEncoding": "ros2msg",
        "schema": "bool success\nstring message",
    },
}


# -- connection and discovery ------------------------------------------------------


async def test_negotiates_the_legacy_subprotocol_and_reads_server_info(
    server: LegacyServer,
) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        assert robot.protocol == "foxglove-ws"
        assert robot.status == "connected"
        info = robot.server_info
        assert info.subprotocol == LEGACY
        assert info.name == "rmb-legacy"
        assert set(info.capabilities) == {"clientPublish", "services"}
        assert set(info.supported_encodings) == {"json", "cdr"}
        # the old server sends "metadata": null and "sessionId": null
        assert info.metadata == {} and info.session_id is None
        assert robot.topics == [] and robot.services == []
    assert robot.status == "closed"


async def test_topics_and_services_with_ids_from_zero(server: LegacyServer) -> None:
    first = add_chatter(server)
    second = add_status(server)
    service = server.add_service(SETBOOL, setbool_handler)
    assert (first, second, service) == (0, 1, 0)
    async with rmb.connect(server.url, options=options()) as robot:
        assert [(t.name, t.schema_name, t.encoding) for t in robot.topics] == [
            ("/chatter", "std_msgs/msg/String", "cdr"),
            ("/status", "demo/Status", "json"),
        ]
        assert [(s.name, s.type) for s in robot.services] == [("/set_flag", "std_srvs/srv/SetBool")]
        # channel 0 and service 0 are usable, not mistaken for "no id"
        async with robot.subscribe("/chatter") as sub:
            assert sub.state == "active"
            await wait_until(lambda: "/chatter" in server.subscribed(), what="subscribe to 0")
            server.send_message(first, cdr_string("zero"), timestamp=5)
            with anyio.fail_after(5):
                msg = await sub.__anext__()
        assert msg.data.to_dict() == {"data": "zero"}
        reply = await robot.call_service("/set_flag", {"data": True}, timeout=5)
        assert reply == SetBool.Response(success=True, message="on")
    assert server.recorder.subscribed == [0]
    assert [r.service_id for r in server.service_requests()] == [0]


async def test_topic_list_follows_runtime_advertise_and_unadvertise(
    server: LegacyServer,
) -> None:
    async with rmb.connect(server.url, options=options()) as robot:
        watcher = robot.watch_topics()
        with anyio.fail_after(5):
            assert await watcher.__anext__() == []
            chan = add_chatter(server)
            assert [t.name for t in await watcher.__anext__()] == ["/chatter"]
            server.remove_channel(chan)
            assert await watcher.__anext__() == []


# -- subscribing -------------------------------------------------------------------------


async def test_subscribe_cdr_string_channel_decodes_messages(server: LegacyServer) -> None:
    chan = add_chatter(server)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: "/chatter" in server.subscribed(), what="subscribe")
            for i in range(3):
                server.send_message(chan, string_msg(f"hello {i}"), timestamp=1000 + i)
            got: list[rmb.Message] = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg)
                    if len(got) == 3:
                        break
    assert [m.data.data for m in got] == ["hello 0", "hello 1", "hello 2"]
    assert [m.log_time_ns for m in got] == [1000, 1001, 1002]
    assert all(m.encoding == "cdr" and m.schema_name == "std_msgs/msg/String" for m in got)
    assert all(m.decode_error is None for m in got)
    assert got[0].byte_size == len(string_msg("hello 0"))
    assert sub.stats.received == 3 and sub.stats.decode_failures == 0


async def test_subscribe_json_channel(server: LegacyServer) -> None:
    chan = add_status(server)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/status") as sub:
            await wait_until(lambda: "/status" in server.subscribed(), what="subscribe")
            server.send_message(chan, json.dumps({"mode": "auto", "speed": 0.5}).encode(), 9)
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.encoding == "json" and msg.schema_name == "demo/Status"
    assert msg.data == {"mode": "auto", "speed": 0.5}
    assert msg.log_time_ns == 9


async def test_channel_removed_while_subscribed_goes_pending_then_resumes(
    server: LegacyServer,
) -> None:
    first = add_chatter(server)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/chatter", buffer=16) as sub:
            await wait_until(lambda: server.subscribed() == ["/chatter"], what="subscribe")
            server.send_message(first, string_msg("before"))
            await wait_until(lambda: sub.stats.received == 1, what="first frame")
            server.remove_channel(first)
            await wait_until(lambda: sub.state == "pending", what="pending after removal")
            assert robot.topics == []
            # nothing arrives for the removed channel
            server.send_message(first, string_msg("lost"))
            second = add_chatter(server)  # re-advertised under a new id
            assert second == first + 1
            await wait_until(lambda: sub.state == "active", what="active after re-advertise")
            await wait_until(lambda: server.subscribed() == ["/chatter", "/chatter"])
            server.send_message(second, string_msg("after"))
            got = []
            with anyio.fail_after(5):
                async for msg in sub:
                    got.append(msg.data.data)
                    if len(got) == 2:
                        break
    assert got == ["before", "after"]
    assert sub.stats.received == 2


# -- publishing ------------------------------------------------------------------------------


def twist_of(received: Any) -> tuple[float, float]:
    """(linear.x, angular.z) of a Twist the client published, either encoding."""
    if received.encoding == "json":
        data = json.loads(received.data)
        return (
            float(data.get("linear", {}).get("x", 0.0)),
            float(data.get("angular", {}).get("z", 0.0)),
        )
    twist = decode("geometry_msgs/msg/Twist", received.data)
    return (twist.linear.x, twist.angular.z)


@pytest.mark.parametrize(
    ("supported", "expected"),
    [
        pytest.param(("json", "cdr"), "cdr", id="cdr"),
        pytest.param(("json",), "json", id="json-only"),
        pytest.param(None, "json", id="encodings-unspecified"),
    ],
)
async def test_publish_reaches_the_server_and_the_zero_twist_arrives_last(
    supported: tuple[str, ...] | None, expected: str
) -> None:
    with LegacyServer(supported_encodings=supported) as srv:
        async with rmb.connect(srv.url, options=options()) as robot:
            await robot.publish(
                "/cmd_vel",
                "geometry_msgs/msg/Twist",
                {"linear": {"x": 0.25}, "angular": {"z": -1.0}},
            )
            await wait_until(lambda: srv.messages("/cmd_vel"), what="the first Twist")
            assert twist_of(srv.messages("/cmd_vel")[0]) == (0.25, -1.0)
        await wait_until(lambda: len(srv.messages("/cmd_vel")) == 2, what="the zero Twist")
        sent = srv.messages("/cmd_vel")
        advertised = srv.advertised()
        assert srv.errors() == []
    assert [twist_of(m) for m in sent] == [(0.25, -1.0), (0.0, 0.0)]
    assert all(m.encoding == expected for m in sent)
    assert len(advertised) == 1
    assert advertised[0]["topic"] == "/cmd_vel"
    assert advertised[0]["encoding"] == expected
    assert advertised[0]["schemaName"] == "geometry_msgs/msg/Twist"
    if expected == "json":
        assert json.loads(sent[-1].data) == {
            "linear": {"x": 0.0, "y": 0.0, "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": 0.0},
        }


async def test_publish_string_then_unadvertise(server: LegacyServer) -> None:
    async with rmb.connect(server.url, options=options(zero_twist_on_exit=False)) as robot:
        await robot.publish("/note", "std_msgs/msg/String", {"data": "hi"})
        await wait_until(lambda: server.messages("/note"), what="the message")
        await robot.unadvertise("/note")
        await wait_until(lambda: server.recorder.unadvertised, what="the unadvertise")
    [msg] = server.messages("/note")
    assert msg.encoding == "cdr" and msg.data == cdr_string("hi")
    assert server.recorder.unadvertised == [server.advertised()[0]["id"]]


# -- services ---------------------------------------------------------------------------------


async def test_service_call_round_trip_cdr(server: LegacyServer) -> None:
    server.add_service(SETBOOL, setbool_handler)
    async with rmb.connect(server.url, options=options()) as robot:
        on = await robot.call_service("/set_flag", {"data": True}, timeout=5)
        off = await robot.call_service("/set_flag", {"data": False}, timeout=5)
    assert on == SetBool.Response(success=True, message="on")
    assert off == SetBool.Response(success=True, message="off")
    requests = server.service_requests()
    assert [(r.service_id, r.encoding, r.payload) for r in requests] == [
        (0, "cdr", b"\x00\x01\x00\x00\x01"),
        (0, "cdr", b"\x00\x01\x00\x00\x00"),
    ]
    assert len({r.call_id for r in requests}) == 2


async def test_service_call_round_trip_json(server: LegacyServer) -> None:
    """The shape of the package's own example: JSON request and response
    with jsonschema schemas."""

    def handle(encoding: str, payload: bytes) -> bytes:
        assert encoding == "json"
        request = json.loads(payload)
        return json.dumps({"success": True, "message": f"got {request['data']}"}).encode()

    def side(name: str, props: dict[str, Any]) -> dict[str, str]:
        return {
            "encoding": "json",
            "schemaName": name,
            "schemaEncoding": "jsonschema",
            "schema": json.dumps({"type": "object", "properties": props}),
        }

    server.add_service(
        {
            "name": "/example_set_bool",
            "type": "example_set_bool",
            "request": side("example/SetBool_Request", {"data": {"type": "boolean"}}),
            "response": side(
                "example/SetBool_Response",
                {"success": {"type": "boolean"}, "message": {"type": "string"}},
            ),
        },
        handle,
    )
    async with rmb.connect(server.url, options=options()) as robot:
        reply = await robot.call_service("/example_set_bool", {"data": True}, timeout=5)
    assert reply == {"success": True, "message": "got True"}
    [request] = server.service_requests()
    assert request.encoding == "json" and json.loads(request.payload) == {"data": True}


async def test_service_with_the_old_flat_schema_fields(server: LegacyServer) -> None:
    """``requestSchema`` / ``responseSchema`` strings, no nested objects: an
    empty request goes out as the bare CDR header."""

    def handle(encoding: str, payload: bytes) -> bytes:
        return cdr_bool_and_string(True, "triggered")

    server.add_service(
        {
            "name": "/trigger",
            "type": "std_srvs/srv/Trigger",
            "requestSchema": "",
            "responseSchema": "bool success\nstring message",
        },
        handle,
    )
    async with rmb.connect(server.url, options=options()) as robot:
        reply = await robot.call_service("/trigger", timeout=5)
    assert reply == Trigger.Response(success=True, message="triggered")
    [request] = server.service_requests()
    assert request.payload == b"\x00\x01\x00\x00"
    assert request.encoding == "cdr"


async def test_failing_service_handler_answers_only_a_status_and_the_call_times_out(
    server: LegacyServer, caplog: pytest.LogCaptureFixture
) -> None:
    """The legacy server turns a handler exception into a level-2 ``status``
    and never answers the call: the call must end at its deadline."""
    caplog.set_level(logging.INFO, logger=LOGGER)

    def broken(encoding: str, payload: bytes) -> bytes:
        raise RuntimeError("the flag is stuck")

    server.add_service(SETBOOL, broken)
    server.errors_expected = True
    async with rmb.connect(server.url, options=options()) as robot:
        with anyio.fail_after(5):
            with pytest.raises(rmb.ServiceTimeout):
                await robot.call_service("/set_flag", {"data": True}, timeout=0.5)
        assert robot.status == "connected"
        # the connection still works afterwards
        server.service_handlers[0] = setbool_handler
        assert await robot.call_service(
            "/set_flag", {"data": False}, timeout=5
        ) == SetBool.Response(success=True, message="off")
    errors = [
        r.getMessage() for r in caplog.records if r.name == LOGGER and r.levelno >= logging.ERROR
    ]
    assert any("the flag is stuck" in text for text in errors), errors
    assert len(server.errors()) == 1  # the one failed call, nothing else


# -- why the client offers all three subprotocols ----------------------------------------


async def test_current_sdk_server_refuses_a_client_offering_only_the_legacy_subprotocol() -> None:
    with SdkServer() as sdk:
        with anyio.fail_after(5):
            with pytest.raises(HandshakeRejected) as info:
                ws = await connect_websocket(sdk.url, subprotocols=(LEGACY,))
                await ws.aclose()
        assert info.value.status == 400
        assert "sec-websocket-protocol" in info.value.body.lower()
        # offering all three (what connect() does) gets the newest
        async with rmb.connect(sdk.url, options=options()) as robot:
            assert robot.server_info.subprotocol == "foxglove.sdk.v1.1"
