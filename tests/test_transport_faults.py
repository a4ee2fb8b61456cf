"""Faults of the WebSocket transport that no real peer commits, against the
scripted server: 1-byte continuation frames, a close frame with the TCP
connection held open, a close code the user must see, and a peer that stops
reading while the client streams."""

from __future__ import annotations

import json
import tracemalloc

import anyio
import pytest
from websockets.frames import Close, Frame, Opcode

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.scripted import SERVER_INFO, Peer, scripted_server
from ros_mobile_bridge.transport import ConnectionLost, connect_websocket

_SUBPROTOCOL = ("foxglove.sdk.v1.1",)
_READ_CHUNK = 1 << 20  # what the transport asks the socket for in one read


def _one_byte_fragments(message: bytes) -> bytes:
    """``message`` as a binary frame and 1-byte continuation frames, on the
    wire (server to client: unmasked, 3 bytes per payload byte)."""
    out = bytearray([0x02, 1, message[0]])
    for byte in message[1:-1]:
        out += bytes((0x00, 1, byte))
    out += bytes((0x80, 1, message[-1]))
    return bytes(out)


async def _send_in_slices(peer: Peer, wire: bytes, size: int = 16 * 1024) -> None:
    view = memoryview(wire)
    for start in range(0, len(view), size):
        await peer.stream.send(view[start : start + size])


@pytest.mark.timeout(300)  # 262k frames parsed with tracemalloc on: a CPU-bound minute when busy
async def test_a_message_in_1_byte_fragments_is_reassembled_in_bounded_memory() -> None:
    size = 256 * 1024  # (the bound's constant part, a read of 1 MiB, needs a large message)
    message = bytes(range(256)) * (size // 256)
    wire = _one_byte_fragments(message)  # built before the measurement starts

    async def fragments(peer: Peer) -> None:
        await _send_in_slices(peer, wire)
        await anyio.sleep(30)

    async with scripted_server(fragments) as url:
        ws = await connect_websocket(url, subprotocols=_SUBPROTOCOL, max_size=1 << 20)
        tracemalloc.start()
        try:
            before = tracemalloc.get_traced_memory()[0]
            with anyio.fail_after(240):
                got = await ws.receive()
            peak = tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()
        await ws.aclose()
    assert got == message
    # The message, its reassembly buffer and one read from the socket: a
    # small constant factor. A list of 1-byte parts and the parser's frame
    # objects for a whole read cost ~150 bytes per byte (39 MB here).
    assert peak - before < 4 * size + _READ_CHUNK, f"peak growth {peak - before} bytes"


async def test_a_fragmented_message_over_max_size_closes_with_1009() -> None:
    closes: list[Close] = []

    async def oversized(peer: Peer) -> None:
        peer.proto.send_frame(Frame(Opcode.BINARY, b"x" * 1024, fin=False))
        for _ in range(8):
            peer.proto.send_frame(Frame(Opcode.CONT, b"x" * 1024, fin=False))
        await peer._flush()
        await peer.drain()
        if peer.proto.close_rcvd is not None:
            closes.append(peer.proto.close_rcvd)

    async with scripted_server(oversized) as url:
        ws = await connect_websocket(url, subprotocols=_SUBPROTOCOL, max_size=4096)
        with anyio.fail_after(10), pytest.raises(ConnectionLost) as caught:
            await ws.receive()
        await ws.aclose()
        await wait_until(lambda: closes, what="the server to see the client's close")
    assert caught.value.code == 1009
    assert "1009" in str(caught.value) and "4096" in str(caught.value), str(caught.value)
    assert closes[0].code == 1009


_SET_BOOL = json.dumps(
    {
        "op": "advertiseServices",
        "services": [
            {
                "id": 3,
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


async def test_the_servers_close_code_and_reason_reach_last_error_and_the_waiters() -> None:
    async def crash(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        await peer.send_text(_SET_BOOL)
        while not isinstance(await peer.recv(), bytes):  # the service call request
            pass
        peer.proto.send_close(1011, "bridge crashed")
        await peer._flush()
        await peer.drain()  # a well-behaved server: it ends TCP after the reply

    options = rmb.ClientOptions(discovery_grace=0, reconnect=None)
    async with scripted_server(crash) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, options=options) as robot:
                await wait_until(lambda: robot.services, what="the service")
                async with robot.subscribe("/never") as sub:
                    with pytest.raises(rmb.NotConnected) as call_error:
                        await robot.call_service("/set_flag", {"data": True}, timeout=10)
                    with pytest.raises(rmb.NotConnected) as iterator_error:
                        async for _ in sub:
                            pass
                assert robot.status == "error"
    error = robot.last_error
    assert isinstance(error, ConnectionLost)
    assert "connection closed by server: 1011 bridge crashed" in str(error), str(error)
    assert (error.code, error.reason) == (1011, "bridge crashed")
    assert "1011 bridge crashed" in str(call_error.value), str(call_error.value)
    assert "1011 bridge crashed" in str(iterator_error.value), str(iterator_error.value)


async def test_a_close_frame_with_the_socket_held_open_ends_the_connection() -> None:
    connections = 0

    async def close_and_hold(peer: Peer) -> None:
        nonlocal connections
        connections += 1
        await peer.send_text(SERVER_INFO)
        if connections == 1:
            await anyio.sleep(0.3)
            peer.proto.send_close(1001, "going away")
            await peer._flush()
            await anyio.sleep(60)  # never reads the reply, never ends TCP
        else:
            await peer.drain()

    options = rmb.ClientOptions(
        discovery_grace=0, reconnect=rmb.ReconnectPolicy(initial_delay=0.05, jitter=0)
    )
    statuses: list[str] = []
    async with scripted_server(close_and_hold) as url:
        with anyio.fail_after(15):
            async with rmb.connect(url, options=options) as robot:

                async def record() -> None:
                    async for status in robot.watch_status():
                        statuses.append(status)

                async with anyio.create_task_group() as tg:
                    tg.start_soon(record)
                    await wait_until(lambda: "reconnecting" in statuses, timeout=5, what="the loss")
                    assert "1001 going away" in str(robot.last_error), robot.last_error
                    await wait_until(
                        lambda: statuses[-1] == "connected" and connections == 2,
                        timeout=5,
                        what="the reconnect",
                    )
                    tg.cancel_scope.cancel()
    assert statuses[:3] == ["connected", "reconnecting", "connected"]


async def test_a_control_publish_to_a_peer_that_stopped_reading_raises() -> None:
    """The peer reads nothing: data publishes fill the socket and the writer
    sticks. The control publish must raise (never return as if sent), and the
    keep-alive must end the connection long before the 10 s send timeout."""

    async def stop_reading(peer: Peer) -> None:
        await peer.send_text(SERVER_INFO)
        peer.stop_reading()
        await anyio.sleep(60)

    options = rmb.ClientOptions(
        discovery_grace=0,
        reconnect=None,
        keepalive_interval=0.5,
        keepalive_timeout=1,
        teardown_timeout=1,
        zero_twist_on_exit=False,
    )
    payload = {"data": "x" * (256 * 1024)}
    async with scripted_server(stop_reading) as url:
        async with rmb.connect(url, options=options) as robot:
            with anyio.fail_after(5):  # data publishes return once queued
                for _ in range(64):  # 16 MiB: more than the socket buffers hold
                    await robot.publish("/bulk", "std_msgs/msg/String", payload)
            start = anyio.current_time()
            with anyio.fail_after(5), pytest.raises(rmb.NotConnected) as caught:
                await robot.publish(
                    "/cmd_vel",
                    "geometry_msgs/msg/Twist",
                    {"linear": {"x": 0.3}},
                    priority="control",
                )
            await wait_until(lambda: robot.status == "error", timeout=5, what="the loss")
            lost_after = anyio.current_time() - start
    assert "keep-alive" in str(caught.value), str(caught.value)
    assert "/cmd_vel was not sent" in str(caught.value), str(caught.value)
    assert "keep-alive" in str(robot.last_error)
    assert lost_after < 5, lost_after  # the send timeout alone would take 10 s
