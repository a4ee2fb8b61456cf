"""Faults a real Foxglove server cannot be made to commit, served by the
scripted peer (``peers.scripted``): bad input is logged and skipped, never a
crash or a hang; a broken handshake or a lost connection is a typed error.

Every test runs on asyncio and trio, and every wait is bounded."""

from __future__ import annotations

import json
import logging
import socket
import struct
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import fast_options, wait_until
from peers.scripted import SERVER_INFO, Peer, scripted_server
from ros_mobile_bridge.transport import HandshakeRejected

# Marked here, not only by conftest: anyio's plugin rebuilds items it marks
# late and would drop the parametrization below.


LOGGER = "ros_mobile_bridge"

ADVERTISE = json.dumps(
    {
        "op": "advertise",
        "channels": [
            {
                "id": 1,
                "topic": "/t",
                "encoding": "json",
                "schemaName": "x/Y",
                "schema": "{}",
                "schemaEncoding": "jsonschema",
            }
        ],
    }
)

SERVICE_ID = 3
ADVERTISE_SERVICES = json.dumps(
    {
        "op": "advertiseServices",
        "services": [
            {
                "id": SERVICE_ID,
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
        ],
    }
)


# these faults end the session; reconnect has its own tests
options = partial(fast_options, discovery_grace=0.05, reconnect=None)


def message_data(sub_id: int, payload: bytes, log_time: int = 7) -> bytes:
    return b"\x01" + struct.pack("<IQ", sub_id, log_time) + payload


async def subscription_id(peer: Peer) -> int:
    """Read the client's ``subscribe`` op; the id of its one subscription."""
    msg = json.loads(await peer.recv())
    assert msg["op"] == "subscribe", msg
    assert [s["channelId"] for s in msg["subscriptions"]] == [1]
    return int(msg["subscriptions"][0]["id"])


async def service_request(peer: Peer) -> tuple[int, int]:
    """Read the client's service call (binary 0x02): (service id, call id)."""
    frame = await peer.recv()
    assert isinstance(frame, bytes) and frame[0] == 0x02, frame
    service_id, call_id, _ = struct.unpack_from("<III", frame, 1)
    return service_id, call_id


async def read_http_request(peer: Peer) -> bytes:
    data = b""
    while b"\r\n\r\n" not in data:
        data += await peer.stream.receive()
    return data


def logged(caplog: pytest.LogCaptureFixture, level: int = logging.WARNING) -> list[str]:
    return [r.getMessage() for r in caplog.records if r.name == LOGGER and r.levelno >= level]


@pytest.fixture
def closed_port() -> int:
    """A 127.0.0.1 port nothing listens on."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -- bad frames after the greeting ----------------------------------------------

GARBAGE = [
    pytest.param("{not json", "not valid JSON", id="malformed-json"),
    pytest.param("[1, 2, 3]", "JSON array, not an object", id="json-array"),
    pytest.param('{"op":"frobnicate","x":1}', "unknown op 'frobnicate'", id="unknown-op"),
    pytest.param(b"\x7f\x00\x00\x00", "unknown binary opcode 0x7f", id="unknown-binary-opcode"),
    pytest.param(b"\x01\x01\x00\x00\x00\x07", "truncated message data", id="truncated-0x01"),
    pytest.param(
        message_data(999, b'{"a":0}'), "unknown subscription id 999", id="0x01-unknown-subscription"
    ),
    pytest.param(
        json.dumps({"op": "serviceCallFailure", "serviceId": 0, "callId": 4242, "message": "gone"}),
        "serviceCallFailure for unknown call 4242",
        id="serviceCallFailure-unknown-call",
    ),
]


@pytest.mark.parametrize(("garbage", "warning"), GARBAGE)
async def test_bad_server_input_is_logged_and_skipped(
    garbage: str | bytes, warning: str, caplog: pytest.LogCaptureFixture
) -> None:
    caplog.set_level(logging.WARNING, logger=LOGGER)

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE)
        sub_id = await subscription_id(peer)
        if isinstance(garbage, str):
            await peer.send_text(garbage)
        else:
            await peer.send_binary(garbage)
        await peer.send_binary(message_data(sub_id, b'{"a":1}'))
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                async with robot.subscribe("/t") as sub:
                    msg = await sub.__anext__()
                    # the garbage came first; the client is still connected after it
                    assert robot.status == "connected"
                    assert robot.last_error is None
    assert msg.data == {"a": 1}
    assert msg.topic == "/t" and msg.log_time_ns == 7
    # nothing from the garbage reached the subscription
    assert sub.stats.received == 1 and sub.stats.decode_failures == 0
    assert any(warning in text for text in logged(caplog)), logged(caplog)
    assert robot.status == "closed"


# -- the greeting -------------------------------------------------------------------


async def test_socket_that_never_sends_server_info_is_a_protocol_mismatch() -> None:
    async def script(peer: Peer) -> None:
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(3):
            with pytest.raises(rmb.ProtocolMismatchError, match="serverInfo") as info:
                async with rmb.connect(url, options=options(connect_timeout=0.5)):
                    pytest.fail("connected without a serverInfo")
    assert info.value.detected is None


async def test_server_accepting_no_subprotocol_is_a_protocol_mismatch() -> None:
    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)  # even a greeting does not make it Foxglove
        await peer.drain()

    async with scripted_server(script, subprotocols=()) as url:
        with anyio.fail_after(5):
            with pytest.raises(rmb.ProtocolMismatchError, match="subprotocol"):
                async with rmb.connect(url, protocol="foxglove-ws", options=options()):
                    pytest.fail("connected without a negotiated subprotocol")
        # "auto" reads a handshake without a subprotocol as rosbridge; the
        # Foxglove greeting that follows then gives the server away
        with anyio.fail_after(5):
            with pytest.raises(rmb.ProtocolMismatchError) as caught:
                async with rmb.connect(url, options=options()):
                    pytest.fail("connected to a Foxglove greeting as rosbridge")
        assert (caught.value.expected, caught.value.detected) == ("rosbridge", "foxglove-ws")


# -- limits -----------------------------------------------------------------------------


@dataclass
class Oversized:
    robot: rmb.Client
    status_inside: str = ""
    errors: dict[str, BaseException] = field(default_factory=dict)
    delivered: list[rmb.Message] = field(default_factory=list)


async def _oversized_message(*, server_closes: bool = True) -> Oversized:
    """A 10 kB message to a client limited to 4096 bytes, while a service
    call and a subscription iterator are pending. With ``server_closes``
    the server answers the client's close like any WebSocket server;
    without, it keeps the TCP connection open and says nothing more."""

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE)
        await peer.send_text(ADVERTISE_SERVICES)
        sub_id = await subscription_id(peer)
        await service_request(peer)
        await peer.send_binary(message_data(sub_id, b"x" * 10_000))
        if server_closes:
            await peer.drain()
        else:
            await anyio.sleep_forever()

    async with scripted_server(script) as url:
        with anyio.fail_after(15):
            async with rmb.connect(url, options=options(max_frame_size=4096)) as robot:
                out = Oversized(robot)
                async with robot.subscribe("/t") as sub:

                    async def call() -> None:
                        try:
                            await robot.call_service("/set_flag", {"data": True}, timeout=30)
                        except rmb.RosBridgeError as exc:
                            out.errors["call"] = exc

                    async def consume() -> None:
                        try:
                            async for msg in sub:
                                out.delivered.append(msg)
                        except rmb.RosBridgeError as exc:
                            out.errors["sub"] = exc

                    # both must fail at once; 5 s is only the bound of a hang
                    with anyio.move_on_after(5):
                        async with anyio.create_task_group() as tg:
                            tg.start_soon(consume)
                            tg.start_soon(call)
                out.status_inside = robot.status
    return out


async def test_message_over_max_frame_size_fails_the_connection_and_everything_pending() -> None:
    out = await _oversized_message()
    assert out.status_inside == "error"
    assert isinstance(out.errors.get("call"), rmb.NotConnected), out.errors
    assert isinstance(out.errors.get("sub"), rmb.NotConnected), out.errors
    assert out.delivered == []
    assert isinstance(out.robot.last_error, rmb.ConnectError)
    assert out.robot.status == "error"


async def test_message_over_max_frame_size_last_error_says_why() -> None:
    out = await _oversized_message()
    reason = str(out.robot.last_error)
    assert "1009" in reason or "4096" in reason or "exceeds" in reason, reason


async def test_message_over_max_frame_size_fails_even_if_the_server_keeps_the_socket() -> None:
    out = await _oversized_message(server_closes=False)
    assert out.status_inside == "error"
    assert isinstance(out.errors.get("call"), rmb.NotConnected), out.errors
    assert isinstance(out.errors.get("sub"), rmb.NotConnected), out.errors


# -- the opening handshake --------------------------------------------------------------


async def test_close_in_the_middle_of_the_handshake_is_a_connect_error() -> None:
    async def script(peer: Peer) -> None:
        await read_http_request(peer)  # then close without answering

    async with scripted_server(script, handshake=False) as url:
        with anyio.fail_after(5):
            with pytest.raises(rmb.ConnectError, match="handshake"):
                async with rmb.connect(url, options=options()):
                    pytest.fail("connected without a handshake")


async def _connect_to_a_non_http_server(*, then_close: bool) -> rmb.ConnectError:
    async def script(peer: Peer) -> None:
        await read_http_request(peer)
        await peer.send_raw(b"SSH-2.0-OpenSSH_9.6\r\n\x00\xff\xfe not http\r\n\r\n")
        if not then_close:
            await peer.stream.receive()  # keep the socket open until the client gives up

    async with scripted_server(script, handshake=False) as url:
        with anyio.fail_after(10):
            with pytest.raises(rmb.ConnectError) as info:
                async with rmb.connect(url, options=options(connect_timeout=2)):
                    pytest.fail("connected to a server that does not speak HTTP")
    return info.value


@pytest.mark.parametrize("then_close", [True, False], ids=["then-close", "then-wait"])
async def test_garbage_instead_of_an_http_response_is_a_connect_error(then_close: bool) -> None:
    error = await _connect_to_a_non_http_server(then_close=then_close)
    assert not isinstance(error, rmb.ProtocolMismatchError)


async def test_garbage_http_response_is_reported_as_such_not_as_a_timeout() -> None:
    """The client has the answer the moment the garbage arrives: it must not
    wait out the connect timeout and then blame the clock."""
    error = await _connect_to_a_non_http_server(then_close=False)
    assert "timed out" not in str(error), str(error)
    assert "HTTP" in str(error) or "handshake" in str(error), str(error)


async def test_server_that_never_answers_the_upgrade_times_out_as_connect_error() -> None:
    async def script(peer: Peer) -> None:
        await read_http_request(peer)
        await peer.stream.receive()  # say nothing; EndOfStream once the client gives up

    async with scripted_server(script, handshake=False) as url:
        with anyio.fail_after(3):
            with pytest.raises(rmb.ConnectError, match="timed out"):
                async with rmb.connect(url, options=options(connect_timeout=0.5)):
                    pytest.fail("connected without an HTTP answer")


async def test_http_400_is_a_connect_error_carrying_the_server_text() -> None:
    body = b"Missing expected sec-websocket-protocol header"

    async def script(peer: Peer) -> None:
        await read_http_request(peer)
        await peer.send_raw(
            b"HTTP/1.1 400 Bad Request\r\n"
            b"Content-Type: text/plain\r\n"
            b"Content-Length: %d\r\n"
            b"Connection: close\r\n\r\n" % len(body) + body
        )

    async with scripted_server(script, handshake=False) as url:
        with anyio.fail_after(5):
            with pytest.raises(rmb.ConnectError) as info:
                async with rmb.connect(url, options=options()):
                    pytest.fail("connected through an HTTP 400")
    assert body.decode() in str(info.value)
    assert isinstance(info.value, HandshakeRejected)
    assert info.value.status == 400


# -- services ---------------------------------------------------------------------------


async def test_service_answered_only_by_a_status_times_out_and_logs_the_status(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER)
    seen: list[tuple[int, int]] = []

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE_SERVICES)
        seen.append(await service_request(peer))
        await peer.send_text(
            json.dumps({"op": "status", "level": 2, "message": "Failed to deserialize request"})
        )
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                with pytest.raises(rmb.ServiceTimeout) as info:
                    await robot.call_service("/set_flag", {"data": True}, timeout=0.5)
                assert robot.status == "connected"
    assert info.value.service == "/set_flag" and info.value.timeout == 0.5
    assert len(seen) == 1 and seen[0][0] == SERVICE_ID
    errors = logged(caplog, logging.ERROR)
    assert any("Failed to deserialize request" in text for text in errors), errors


# -- a lost connection ----------------------------------------------------------------


async def test_connection_dropped_while_a_call_is_pending_fails_the_call() -> None:
    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE_SERVICES)
        await service_request(peer)
        # return: the TCP stream closes without a close frame

    async with scripted_server(script) as url:
        with anyio.fail_after(5):  # far below the call's own 30 s
            async with rmb.connect(url, options=options()) as robot:
                with pytest.raises(rmb.NotConnected):
                    await robot.call_service("/set_flag", {"data": True}, timeout=30)
                assert robot.status == "error"
                assert isinstance(robot.last_error, rmb.ConnectError)
                with pytest.raises(rmb.NotConnected):
                    await robot.call_service("/set_flag", {"data": True}, timeout=30)
    assert robot.status == "error"


async def _publish_then_lose_the_connection() -> rmb.Client:
    received: list[str | bytes] = []

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        while not any(isinstance(m, bytes) for m in received):
            received.append(await peer.recv())  # advertise, then the Twist
        # return: the connection drops

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.5}})
                await wait_until(lambda: robot.status == "error", what="the loss to be noticed")
            # leaving the block neither hung nor raised
    assert json.loads(received[0])["op"] == "advertise"
    assert len(received) == 2
    return robot


async def test_leaving_the_block_after_the_connection_was_lost_neither_hangs_nor_raises(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER)
    robot = await _publish_then_lose_the_connection()
    assert robot.status == "error"
    assert isinstance(robot.last_error, rmb.ConnectError)
    assert any("connection lost" in text for text in logged(caplog)), logged(caplog)
    # nothing claims a zero Twist went out
    assert not any("zero Twist sent" in r.getMessage() for r in caplog.records)


async def test_teardown_after_a_loss_logs_that_the_zero_twist_could_not_be_sent(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER)
    await _publish_then_lose_the_connection()
    teardown = [
        r.getMessage()
        for r in caplog.records
        if r.name == LOGGER and r.levelno >= logging.WARNING and "/cmd_vel" in r.getMessage()
    ]
    assert teardown, logged(caplog)


# -- bad arguments and refused connections ---------------------------------------------


@pytest.mark.parametrize(
    ("target", "kwargs", "error"),
    [
        pytest.param("", {}, ValueError, id="empty"),
        pytest.param("host:99999", {}, ValueError, id="port-out-of-range"),
        pytest.param("::1", {}, ValueError, id="ipv6-without-brackets"),
        pytest.param("ftp://x", {}, ValueError, id="unsupported-scheme"),
        pytest.param("LOCAL", {"protocol": "bogus"}, ValueError, id="bad-protocol"),
        pytest.param("LOCAL", {"options": "x"}, TypeError, id="options-not-ClientOptions"),
        pytest.param("LOCAL", {"port": "8765"}, TypeError, id="port-not-int"),
        pytest.param("LOCAL", {"secure": "yes"}, TypeError, id="secure-not-bool"),
        pytest.param(None, {}, TypeError, id="target-not-str"),
    ],
)
async def test_bad_arguments_raise_at_once_before_any_network_io(
    target: str | None, kwargs: dict[str, Any], error: type[Exception], closed_port: int
) -> None:
    # "LOCAL" is a port nothing listens on: a connection attempt would be a
    # ConnectError, so ValueError / TypeError proves none was made.
    if target == "LOCAL":
        target = f"127.0.0.1:{closed_port}"
    with anyio.fail_after(2):
        with pytest.raises(error):
            async with rmb.connect(target, **kwargs):  # type: ignore[arg-type]
                pytest.fail("connected with bad arguments")


async def test_connection_refused_is_a_connect_error(closed_port: int) -> None:
    with anyio.fail_after(5):
        with pytest.raises(rmb.ConnectError) as info:
            async with rmb.connect(f"127.0.0.1:{closed_port}", options=options()):
                pytest.fail("connected to a closed port")
    assert not isinstance(info.value, rmb.ProtocolMismatchError)


# -- limits: skipped or refused, counted, never fatal ---------------------------------


def rejected(caplog: pytest.LogCaptureFixture) -> list[str]:
    return [t for t in logged(caplog) if t.startswith("skipped input from the server")]


async def test_text_frame_with_invalid_utf8_is_skipped_and_counted(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger=LOGGER)

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE)
        sub_id = await subscription_id(peer)
        peer.proto.send_text(b'{"op":"status","level":0,"message":"\xff\xfe"}')  # not UTF-8
        await peer._flush()
        await peer.send_binary(message_data(sub_id, b'{"a":1}'))
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                async with robot.subscribe("/t") as sub:
                    msg = await sub.__anext__()
                    assert robot.status == "connected" and robot.last_error is None
                    assert robot.rejections == {"invalid_utf8": 1}
    assert msg.data == {"a": 1}
    assert len(rejected(caplog)) == 1 and "invalid_utf8" in rejected(caplog)[0]


async def test_huge_status_text_is_logged_truncated(caplog: pytest.LogCaptureFixture) -> None:
    caplog.set_level(logging.INFO, logger=LOGGER)
    text = "x" * 2_000_000

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE)
        sub_id = await subscription_id(peer)
        await peer.send_text(json.dumps({"op": "status", "level": 2, "message": text}))
        await peer.send_binary(message_data(sub_id, b'{"a":1}'))
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                async with robot.subscribe("/t") as sub:
                    await sub.__anext__()
    status = [t for t in logged(caplog, logging.INFO) if t.startswith("server status")]
    assert len(status) == 1
    assert len(status[0]) < 1000 and "2000000 characters" in status[0]


def channels_advertise(first: int, count: int) -> str:
    return json.dumps(
        {
            "op": "advertise",
            "channels": [
                {"id": i, "topic": f"/c{i:06d}", "encoding": "json", "schemaName": "x/Y"}
                for i in range(first, first + count)
            ],
        }
    )


async def test_channels_beyond_max_channels_are_refused_once_per_advertise(
    caplog: pytest.LogCaptureFixture,
) -> None:
    caplog.set_level(logging.WARNING, logger=LOGGER)
    done = anyio.Event()

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(channels_advertise(0, 5))
        await peer.send_text(channels_advertise(5, 5))
        await peer.send_text(json.dumps({"op": "unadvertise", "channelIds": [0]}))
        await peer.send_text(channels_advertise(10, 1))
        await peer.send_text(json.dumps({"op": "status", "level": 0, "message": "done"}))
        await done.wait()
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options(max_channels=3)) as robot:
                await wait_until(lambda: "/c000010" in [t.name for t in robot.topics])
                await wait_until(lambda: robot.rejections.get("channel_limit") == 2)
                done.set()
                assert [t.name for t in robot.topics] == ["/c000001", "/c000002", "/c000010"]
                assert robot.rejections == {"channel_limit": 2}
                assert robot.status == "connected"
    assert len(rejected(caplog)) == 2  # one line per advertisement, not per channel


async def test_topic_list_follows_incremental_advertisements() -> None:
    """The topic list is kept per advertisement, not rebuilt: it must stay
    exactly what a rebuild would give (sorted, one entry per topic, the
    topic's remaining channel after an unadvertise, a re-advertised id
    moving to its new topic)."""
    done = anyio.Event()

    def channel(cid: int, topic: str, schema: str) -> dict[str, Any]:
        return {"id": cid, "topic": topic, "encoding": "json", "schemaName": schema}

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(
            json.dumps(
                {
                    "op": "advertise",
                    "channels": [channel(1, "/b", "x/B"), channel(2, "/a", "x/A")],
                }
            )
        )
        await peer.send_text(
            json.dumps({"op": "advertise", "channels": [channel(3, "/b", "x/B2")]})
        )
        await peer.send_text(json.dumps({"op": "unadvertise", "channelIds": [1]}))
        # id 2 re-advertised as another topic: /a is gone
        await peer.send_text(json.dumps({"op": "advertise", "channels": [channel(2, "/c", "x/C")]}))
        await done.wait()
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                await wait_until(lambda: "/c" in [t.name for t in robot.topics])
                done.set()
                topics = [(t.name, t.schema_name) for t in robot.topics]
    assert topics == [("/b", "x/B2"), ("/c", "x/C")]


async def test_schema_over_max_schema_fields_is_refused_and_messages_arrive_raw() -> None:
    sent = anyio.Event()
    cdr_advertise = json.dumps(
        {
            "op": "advertise",
            "channels": [
                {
                    "id": 1,
                    "topic": "/t",
                    "encoding": "cdr",
                    "schemaName": "x/msg/Three",
                    "schema": "float64 a\nfloat64 b\nfloat64 c\n",
                    "schemaEncoding": "ros2msg",
                }
            ],
        }
    )

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(cdr_advertise)
        sub_id = await subscription_id(peer)
        await peer.send_binary(message_data(sub_id, b"\x00\x01\x00\x00" + bytes(24)))
        sent.set()
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options(max_schema_fields=2)) as robot:
                async with robot.subscribe("/t") as sub:
                    msg = await sub.__anext__()
                    assert robot.rejections == {"schema_too_large": 1}
    assert isinstance(msg.data, memoryview) and msg.data.nbytes == 28


async def test_decoder_is_built_off_the_event_loop_before_the_first_message() -> None:
    """Building a CDR decoder (schema parse + code generation) runs in a
    worker thread at subscribe time, not in the reader on the first message."""
    import threading

    from ros_mobile_bridge.codec import CodecRegistry

    threads: list[int] = []
    original = CodecRegistry.decoder

    def spy(self: CodecRegistry, name: str, encoding: str) -> Any:
        threads.append(threading.get_ident())
        return original(self, name, encoding)

    cdr_advertise = json.dumps(
        {
            "op": "advertise",
            "channels": [
                {
                    "id": 1,
                    "topic": "/t",
                    "encoding": "cdr",
                    "schemaName": "x/msg/Pair",
                    "schema": "float64 a\nfloat64 b\n",
                    "schemaEncoding": "ros2msg",
                }
            ],
        }
    )

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(cdr_advertise)
        sub_id = await subscription_id(peer)
        await peer.send_binary(
            message_data(sub_id, b"\x00\x01\x00\x00" + struct.pack("<dd", 1.5, 2.5))
        )
        await peer.drain()

    loop_thread = threading.get_ident()
    mp = pytest.MonkeyPatch()
    mp.setattr(CodecRegistry, "decoder", spy)
    try:
        async with scripted_server(script) as url:
            with anyio.fail_after(10):
                async with rmb.connect(url, options=options()) as robot:
                    async with robot.subscribe("/t") as sub:
                        msg = await sub.__anext__()
    finally:
        mp.undo()
    assert msg.data.to_dict() == {"a": 1.5, "b": 2.5}
    assert threads and loop_thread not in threads


async def test_call_beyond_max_pending_requests_raises_at_once() -> None:
    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(ADVERTISE_SERVICES)
        await peer.drain()  # never answers

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options(max_pending_requests=1)) as robot:
                async with anyio.create_task_group() as tg:
                    tg.start_soon(robot.call_service, "/set_flag", {"data": True})
                    await wait_until(lambda: len(robot._conn.adapter._calls) == 1)  # type: ignore[attr-defined]
                    with anyio.fail_after(1):  # at once, not at the 10 s timeout
                        with pytest.raises(rmb.ServiceError, match="max_pending_requests"):
                            await robot.call_service("/set_flag", {"data": False})
                    tg.cancel_scope.cancel()


async def test_a_lost_connection_fails_the_graph_asset_and_playback_waits() -> None:
    """A server that takes the requests and closes before any answer: each
    waiting call ends with the lost connection, not at its 30 s deadline."""
    info = (
        '{"op":"serverInfo","name":"scripted","capabilities":["connectionGraph","assets",'
        '"playbackControl"],"supportedEncodings":["json","cdr"],"metadata":{}}'
    )
    asked: list[str | bytes] = []

    async def script(peer: Peer) -> None:
        await peer.send_text(info)
        while len(asked) < 3:  # subscribeConnectionGraph, fetchAsset, the playback request
            asked.append(await peer.recv())
        # closing without an answer: the script ends

    errors: dict[str, BaseException] = {}

    async def fail(name: str, call: Any) -> None:
        try:
            await call()
        except rmb.RosBridgeError as exc:
            errors[name] = exc

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            opts = options(service_timeout=30.0, reconnect=None)
            async with rmb.connect(url, options=opts) as robot:
                async with anyio.create_task_group() as tg:
                    tg.start_soon(fail, "nodes", robot.nodes)
                    tg.start_soon(fail, "asset", partial(robot.fetch_asset, "package://a/b"))
                    request = rmb.PlaybackRequest(play=True)
                    tg.start_soon(fail, "playback", partial(robot.control_playback, request))
    assert sorted(errors) == ["asset", "nodes", "playback"]
    assert all(isinstance(e, rmb.NotConnected) for e in errors.values()), errors
    assert sum(isinstance(m, bytes) for m in asked) == 1  # the playback request is binary


async def test_status_ids_kept_are_bounded_and_an_unknown_playback_status_is_refused(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """A server sending statuses with ever new ids costs a bounded table: a
    withdrawal of one forgotten is logged without its message; a playback
    state of a status the protocol does not define is counted and skipped."""
    caplog.set_level(logging.INFO, logger=LOGGER)

    async def script(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        asked = json.loads(await peer.recv())  # the client watches from now on
        await peer.send_text(
            json.dumps({"op": "parameterValues", "parameters": [], "id": asked["id"]})
        )
        for i in range(1500):
            await peer.send_text(f'{{"op":"status","level":1,"message":"m{i}","id":"s{i}"}}')
        await peer.send_text('{"op":"removeStatus","statusIds":["s0","s1499"]}')
        await peer.send_binary(b"\x05\x09" + struct.pack("<QfBI", 1, 1.0, 0, 0))
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options()) as robot:
                events = robot.watch_server_status()
                assert await robot.list_parameters() == {}
                removed = await wait_for_removal(events)
                await wait_until(lambda: robot.rejections.get("malformed") == 1)
                assert robot.playback_state is None
    assert removed == rmb.StatusRemoved(("s0", "s1499"))
    records = [(r.levelno, r.getMessage()) for r in caplog.records if r.name == LOGGER]
    assert (logging.INFO, "server status s0 withdrawn") in records
    assert (logging.WARNING, "server status s1499 withdrawn: m1499") in records


async def wait_for_removal(events: Any) -> rmb.StatusRemoved:
    async for event in events:
        if isinstance(event, rmb.StatusRemoved):
            return event
    raise AssertionError("no removeStatus")


async def test_a_connection_graph_is_bounded_and_its_malformed_entries_counted() -> None:
    info = (
        '{"op":"serverInfo","name":"scripted","capabilities":["connectionGraph"],'
        '"supportedEncodings":["cdr"],"metadata":{}}'
    )
    published = [{"name": f"/t{i}", "publisherIds": [f"/n{i}"]} for i in range(3)]
    update = {
        "op": "connectionGraphUpdate",
        "publishedTopics": [*published, {"publisherIds": ["/nameless"]}, {"name": "/no_ids"}],
        "subscribedTopics": [],
        "advertisedServices": [],
        "removedTopics": [],
        "removedServices": [],
    }
    asked: list[str | bytes] = []

    async def script(peer: Peer) -> None:
        await peer.send_text(info)
        asked.append(await peer.recv())
        await peer.send_text(json.dumps(update))
        asked.append(await peer.recv())
        await peer.drain()

    async with scripted_server(script) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options(max_channels=2)) as robot:
                assert await robot.nodes() == ["/n0", "/n1"]
                await wait_until(lambda: robot.rejections.get("malformed") == 2)
                assert robot.rejections["channel_limit"] == 1
                await wait_until(lambda: len(asked) == 2)
    assert [json.loads(m)["op"] for m in asked] == [
        "subscribeConnectionGraph",
        "unsubscribeConnectionGraph",
    ]
