"""Faults a real rosbridge server cannot be made to commit, served by the
scripted peer (``peers.scripted``) speaking just enough rosbridge: garbage,
unknown ops, fragments that never complete or arrive too late or too big,
escaped topics, a drop with calls and goals pending. Bad input is logged and
skipped, never a crash or a hang.

Every test runs on asyncio and trio, and every wait is bounded."""

from __future__ import annotations

import json
import logging
from collections.abc import Awaitable, Callable
from functools import partial
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.scripted import Peer, scripted_server
from ros_mobile_bridge.interfaces.std_msgs.msg import String
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool

LOGGER = "ros_mobile_bridge"
TOPICS = {
    "topics": ["/chatter", "/cmd_vel"],
    "types": ["std_msgs/msg/String", "geometry_msgs/msg/Twist"],
}


options = partial(
    rmb.ClientOptions,
    connect_timeout=3.0,
    reconnect=None,
    teardown_timeout=1.0,
    latency_probe_interval=0,
    keepalive_interval=0,
)


def publish(topic: str, data: str) -> str:
    return json.dumps({"op": "publish", "topic": topic, "msg": {"data": data}})


def fragments(frame: str, size: int, frag_id: str = "rosbridge:1") -> list[str]:
    parts = [frame[i : i + size] for i in range(0, len(frame), size)]
    return [
        json.dumps({"op": "fragment", "id": frag_id, "data": p, "num": n, "total": len(parts)})
        for n, p in enumerate(parts)
    ]


class FakeBridge:
    """Answers the rosapi calls a client makes, records every frame, and runs
    ``on_subscribe`` when the client subscribes."""

    def __init__(
        self,
        on_subscribe: Callable[[Peer, dict[str, Any]], Awaitable[None]] | None = None,
        *,
        rosapi: bool = True,
        answer_topics: bool = True,
    ) -> None:
        self.on_subscribe = on_subscribe
        self.rosapi = rosapi
        self.answer_topics = answer_topics
        self.received: list[dict[str, Any]] = []
        self.peers: list[Peer] = []

    async def __call__(self, peer: Peer) -> None:
        self.peers.append(peer)
        while True:
            frame = await peer.recv()
            obj = json.loads(frame)
            self.received.append(obj)
            op = obj.get("op")
            if op == "call_service" and obj["service"].startswith("/rosapi/"):
                await self._rosapi(peer, obj)
            elif op == "subscribe" and self.on_subscribe is not None:
                await self.on_subscribe(peer, obj)

    async def _rosapi(self, peer: Peer, obj: dict[str, Any]) -> None:
        service = obj["service"]
        if service == "/rosapi/topics" and not self.answer_topics:
            return
        if not self.rosapi:
            await peer.send_text(
                json.dumps(
                    {
                        "op": "service_response",
                        "service": service,
                        "result": False,
                        "values": "type is required when interface is absent from ROS graph",
                        "id": obj.get("id"),
                    }
                )
            )
            return
        values: Any = {
            "/rosapi/topics": TOPICS,
            "/rosapi/services": {"services": ["/set_flag"]},
            "/rosapi/service_type": {
                "type": {"/set_flag": "std_srvs/srv/SetBool"}.get(
                    (obj.get("args") or {}).get("service"), ""
                )
            },
            "/rosapi/get_time": {"time": {"sec": 1, "nanosec": 2}},
            "/rosapi/action_servers": {"action_servers": ["/fibonacci"]},
        }.get(service, {})
        await peer.send_text(
            json.dumps(
                {
                    "op": "service_response",
                    "service": service,
                    "result": True,
                    "values": values,
                    "id": obj.get("id"),
                }
            )
        )

    def sent(self, op: str) -> list[dict[str, Any]]:
        return [f for f in self.received if f.get("op") == op]

    def polls(self) -> int:
        """The client's discovery polls so far: its ``/rosapi/topics`` calls
        (a client polls again only once its last poll ended)."""
        return sum(f["service"] == "/rosapi/topics" for f in self.sent("call_service"))


async def first_messages(sub: rmb.Subscription, n: int) -> list[rmb.Message]:
    got: list[rmb.Message] = []
    with anyio.fail_after(5):
        async for msg in sub:
            got.append(msg)
            if len(got) == n:
                break
    return got


async def test_garbage_is_logged_and_skipped(caplog: pytest.LogCaptureFixture) -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        await peer.send_text("this is not json")
        await peer.send_text("[1, 2, 3]")
        await peer.send_text('{"no_op": true}')
        await peer.send_text('{"op":"bogus_op"}')
        await peer.send_text('{"op":"png","data":"iVBORw0KGgo="}')
        await peer.send_binary(b"\xff\x00garbage")
        await peer.send_text(publish("/never_subscribed", "stray"))
        await peer.send_text('{"op":"service_response","id":"nobody","result":"yes"}')
        await peer.send_text('{"op":"publish","topic":"/chatter","msg":')  # truncated
        await peer.send_text(publish("/chatter", "good"))

    bridge = FakeBridge(on_subscribe)
    caplog.set_level(logging.INFO, LOGGER)
    async with scripted_server(bridge, subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
            async with robot.subscribe("/chatter") as sub:
                got = await first_messages(sub, 2)
                assert robot.status == "connected"
    # the truncated frame is delivered raw with its decode error, the next is whole
    assert got[0].decode_error is not None
    assert got[1].data.to_dict() == {"data": "good"}
    text = caplog.text
    for needle in (
        "not JSON",
        "unknown op 'bogus_op'",
        "png",
        "never subscribed",
        "malformed CBOR",
    ):
        assert needle in text, needle


async def test_escaped_topic_and_reordered_keys_are_recognised() -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        # Python rosbridge with ujson: spaces and "\/" escapes
        await peer.send_text('{"op": "publish", "topic": "\\/chatter", "msg": {"data": "a"}}')
        await peer.send_text('{"topic":"/chatter","op":"publish","msg":{"data":"b"}}')
        await peer.send_text('{"msg":{"data":"c"},"op":"publish","topic":"/chatter"}')

    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
            async with robot.subscribe("/chatter") as sub:
                got = await first_messages(sub, 3)
    assert [m.data for m in got] == [String(data="a"), String(data="b"), String(data="c")]
    assert {m.topic for m in got} == {"/chatter"}


async def test_fragments_are_reassembled_in_any_order() -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        parts = fragments(publish("/chatter", "x" * 300), 64)
        for part in reversed(parts):
            await peer.send_text(part)
        await peer.send_text(publish("/chatter", "after"))

    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
            async with robot.subscribe("/chatter") as sub:
                got = await first_messages(sub, 2)
    assert [m.data.data for m in got] == ["x" * 300, "after"]


async def test_incomplete_late_and_oversized_fragments_are_dropped(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        # never completed: part 1 of 3 is missing
        parts = fragments(publish("/chatter", "lost"), 20, "rosbridge:1")
        for part in (parts[0], parts[2]):
            await peer.send_text(part)
        # too late: the last part arrives after the fragment timeout
        late = fragments(publish("/chatter", "late"), 20, "rosbridge:2")
        for part in late[:-1]:
            await peer.send_text(part)
        await anyio.sleep(0.5)
        await peer.send_text(late[-1])
        # too big for max_frame_size (2048 bytes)
        for part in fragments(publish("/chatter", "y" * 3000), 500, "rosbridge:3"):
            await peer.send_text(part)
        await peer.send_text(publish("/chatter", "whole"))

    caplog.set_level(logging.INFO, LOGGER)
    opts = options(fragment_timeout=0.2, max_frame_size=2048)
    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=opts) as robot:
            async with robot.subscribe("/chatter") as sub:
                got = await first_messages(sub, 1)
                with anyio.move_on_after(0.3):
                    got += await first_messages(sub, 1)
    assert [m.data for m in got] == [String(data="whole")]
    assert "over 2048 characters" in caplog.text


async def test_call_service_forwards_its_timeout_and_never_zero() -> None:
    async def script(peer: Peer) -> None:
        bridge = FakeBridge()
        bridge.peers.append(peer)
        while True:
            obj = json.loads(await peer.recv())
            calls.append(obj)
            if obj["service"].startswith("/rosapi/"):
                await bridge._rosapi(peer, obj)
            else:  # answer the user's call like the Rust bridge does at its timeout
                await peer.send_text(
                    json.dumps(
                        {
                            "op": "service_response",
                            "service": obj["service"],
                            "values": "Timeout exceeded while waiting for service response",
                            "result": False,
                            "id": obj["id"],
                        }
                    )
                )

    calls: list[dict[str, Any]] = []
    async with scripted_server(script, subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
            with pytest.raises(rmb.ServiceTimeout, match="Timeout exceeded") as caught:
                await robot.call_service("/set_flag", {"data": True}, timeout=2.5)
            assert caught.value.timeout == 2.5
            with pytest.raises(ValueError, match="positive"):
                await robot.call_service("/set_flag", {}, timeout=0)
    user = [c for c in calls if c["service"] == "/set_flag"]
    assert len(user) == 1
    assert user[0]["timeout"] == 2.5
    assert user[0]["args"] == {"data": True}
    assert all(c.get("timeout", 1) > 0 for c in calls)


async def test_a_drop_fails_pending_calls_and_goals() -> None:
    async def script(peer: Peer) -> None:
        bridge = FakeBridge()
        while True:
            obj = json.loads(await peer.recv())
            if obj["service" if "service" in obj else "op"].startswith("/rosapi/"):
                await bridge._rosapi(peer, obj)
            elif obj["op"] == "send_action_goal":
                await peer.send_text(
                    json.dumps(
                        {
                            "op": "action_feedback",
                            "action": obj["action"],
                            "values": {"sequence": [0]},
                            "id": obj["id"],
                        }
                    )
                )
            elif obj["op"] == "call_service":
                await peer.stream.aclose()  # drop, with both pending
                return

    async with scripted_server(script, subprotocols=()) as url:
        async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
            async with robot.send_action_goal(
                "/fibonacci", "test_msgs/action/Fibonacci", {"order": 5}
            ) as goal:
                await goal.accepted()
                with anyio.fail_after(5), pytest.raises(rmb.NotConnected):
                    await robot.call_service("/set_flag", {"data": True})
                with anyio.fail_after(5), pytest.raises(rmb.ActionGoalError) as caught:
                    await goal.result()
                assert caught.value.reason == "disconnected"
                assert goal.state == "failed"


async def test_no_answer_to_discovery_is_a_protocol_mismatch() -> None:
    async with scripted_server(FakeBridge(answer_topics=False), subprotocols=()) as url:
        with anyio.fail_after(5), pytest.raises(rmb.ProtocolMismatchError) as caught:
            async with rmb.connect(url, protocol="rosbridge", options=options(connect_timeout=0.5)):
                pytest.fail("connected to a server that never answered")
    assert caught.value.expected == "rosbridge"
    assert caught.value.detected is None


async def test_a_bridge_without_rosapi_still_subscribes_and_publishes(
    caplog: pytest.LogCaptureFixture,
) -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        await peer.send_text(publish(obj["topic"], "typed"))

    caplog.set_level(logging.WARNING, LOGGER)
    bridge = FakeBridge(on_subscribe, rosapi=False)
    async with scripted_server(bridge, subprotocols=()) as url:
        opts = options(discovery_interval=0.05)
        async with rmb.connect(url, protocol="rosbridge", options=opts) as robot:
            assert robot.topics == []
            async with robot.subscribe("/chatter", schema="std_msgs/msg/String") as sub:
                got = await first_messages(sub, 1)
            # several failed polls (each ended when the next begins): warned once
            await wait_until(lambda: bridge.polls() >= 4, what="four discovery polls")
    assert got[0].data.to_dict() == {"data": "typed"}
    assert bridge.sent("subscribe")[0]["type"] == "std_msgs/msg/String"
    assert caplog.text.count("discovery through /rosapi failed") == 1


async def test_a_foxglove_frame_on_a_rosbridge_connection_is_a_mismatch() -> None:
    async def script(peer: Peer) -> None:
        await peer.send_text(
            json.dumps({"op": "advertise", "channels": [{"id": 1, "topic": "/t"}]})
        )
        await peer.drain()

    async with scripted_server(script, subprotocols=()) as url:
        with anyio.fail_after(5), pytest.raises(rmb.ProtocolMismatchError) as caught:
            async with rmb.connect(url, protocol="rosbridge", options=options()):
                pytest.fail("connected to a Foxglove server as rosbridge")
    assert caught.value.detected == "foxglove-ws"


async def test_oversized_frame_fails_the_connection_clearly() -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        await peer.send_text(publish("/chatter", "z" * 5000))
        await peer.drain()

    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        opts = options(max_frame_size=2048)
        async with rmb.connect(url, protocol="rosbridge", options=opts) as robot:
            async with robot.subscribe("/chatter") as sub:
                with anyio.fail_after(5), pytest.raises(rmb.NotConnected):
                    async for _ in sub:
                        pytest.fail("an oversized message was delivered")
            await wait_until(lambda: robot.status == "error")
            assert "2048" in str(robot.last_error) or "1009" in str(robot.last_error)


def test_message_details_become_a_definition_the_codec_reads() -> None:
    """``/rosapi/message_details`` as rosbridge_server_rs answers it (IDL-ish
    primitive names, ``pkg/Name`` types, -1 / 0 / N array lengths) turns
    into ``.msg`` text that decodes CDR (the cbor-raw path for types the
    bundled definitions lack)."""
    from ros_mobile_bridge.adapters._rosbridge_definitions import typedefs_to_msg
    from ros_mobile_bridge.codec import CodecRegistry

    answer = {
        "typedefs": [
            {
                "type": "my_pkg/Reading",
                "fieldnames": ["header", "ok", "raw", "gain", "values", "corners"],
                "fieldtypes": ["std_msgs/Header", "boolean", "octet", "float", "double", "double"],
                "fieldarraylen": [-1, -1, -1, -1, 0, 4],
            },
            {
                "type": "std_msgs/Header",
                "fieldnames": ["stamp", "frame_id"],
                "fieldtypes": ["builtin_interfaces/Time", "string"],
                "fieldarraylen": [-1, -1],
            },
        ]
    }
    text = typedefs_to_msg("my_pkg/msg/Reading", answer)
    assert "bool ok" in text and "byte raw" in text and "float32 gain" in text
    assert "float64[] values" in text and "float64[4] corners" in text
    codecs = CodecRegistry()
    codecs.add_schema("my_pkg/msg/Reading", "ros2msg", text)
    data = {"ok": True, "raw": 7, "gain": 0.5, "values": [1.5, 2.5], "corners": [1, 2, 3, 4]}
    encoded = codecs.encoder("my_pkg/msg/Reading", "cdr")(data)
    decoded = codecs.decoder("my_pkg/msg/Reading", "cdr")(memoryview(encoded))
    assert decoded.ok is True and decoded.raw == 7 and decoded.gain == 0.5
    assert list(decoded.values) == [1.5, 2.5] and list(decoded.corners) == [1, 2, 3, 4]
    with pytest.raises(ValueError, match="do not define"):
        typedefs_to_msg("other/msg/Thing", answer)


# -- limits: skipped or refused, counted, never fatal ---------------------------------


async def test_cbor_bignum_status_is_logged_bounded_and_the_connection_stays(
    caplog: pytest.LogCaptureFixture,
) -> None:
    import cbor2

    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        await peer.send_binary(cbor2.dumps({"op": "status", "level": "error", "msg": 1 << 20000}))
        await peer.send_binary(cbor2.dumps({"op": "status", "level": 1 << 20000, "msg": "m"}))
        await peer.send_text(publish("/chatter", "after"))

    caplog.set_level(logging.INFO, LOGGER)
    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    (msg,) = await first_messages(sub, 1)
                    assert robot.status == "connected" and robot.last_error is None
    assert msg.data.to_dict() == {"data": "after"}
    status = [r.getMessage() for r in caplog.records if "server status" in r.getMessage()]
    assert len(status) == 2 and all(len(t) < 1000 for t in status)
    assert "20001 bits" in status[0]


async def test_huge_status_text_is_logged_truncated(caplog: pytest.LogCaptureFixture) -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        await peer.send_text(json.dumps({"op": "status", "level": "error", "msg": "y" * 1_000_000}))
        await peer.send_text(publish("/chatter", "after"))

    caplog.set_level(logging.INFO, LOGGER)
    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await first_messages(sub, 1)
    status = [r.getMessage() for r in caplog.records if "server status" in r.getMessage()]
    assert len(status) == 1 and len(status[0]) < 1000 and "1000000 characters" in status[0]


async def test_fragment_bounds_breaches_are_counted() -> None:
    async def on_subscribe(peer: Peer, obj: dict[str, Any]) -> None:
        # 17 messages in reassembly: the oldest is dropped
        for i in range(17):
            await peer.send_text(fragments(publish("/chatter", "x" * 40), 20, f"m{i}")[0])
        await peer.send_text(publish("/chatter", "after"))

    async with scripted_server(FakeBridge(on_subscribe), subprotocols=()) as url:
        with anyio.fail_after(10):
            async with rmb.connect(url, protocol="rosbridge", options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await first_messages(sub, 1)
                    assert robot.rejections == {"fragment_limit": 1}


async def test_discovered_topics_beyond_max_channels_are_refused_and_counted_once() -> None:
    bridge = FakeBridge()
    async with scripted_server(bridge, subprotocols=()) as url:
        with anyio.fail_after(10):
            opts = options(max_channels=1, discovery_interval=0.05)
            async with rmb.connect(url, protocol="rosbridge", options=opts) as robot:
                assert [t.name for t in robot.topics] == ["/chatter"]
                await wait_until(lambda: robot.rejections.get("channel_limit") == 1)
                # three more polls ended (a fourth began), all still over the bound
                polls = bridge.polls()
                await wait_until(lambda: bridge.polls() >= polls + 4, what="four more polls")
                assert robot.rejections == {"channel_limit": 1}


async def test_call_beyond_max_pending_requests_raises_at_once() -> None:
    async with scripted_server(FakeBridge(), subprotocols=()) as url:
        with anyio.fail_after(10):
            opts = options(max_pending_requests=1)
            async with rmb.connect(url, protocol="rosbridge", options=opts) as robot:
                async with anyio.create_task_group() as tg:
                    # a non-rosapi service the fake bridge never answers
                    tg.start_soon(robot.call_service, "/set_flag", {"data": True})
                    await wait_until(lambda: len(robot._conn.adapter._calls.pending) == 1)  # type: ignore[attr-defined]
                    with anyio.fail_after(1):
                        with pytest.raises(rmb.ServiceError, match="max_pending_requests"):
                            await robot.call_service("/set_flag", {"data": False})
                    tg.cancel_scope.cancel()


async def test_messages_read_with_a_reply_are_delivered_before_it_resolves_the_call() -> None:
    """Frames that arrive in one read are handled as a batch: the messages
    before a service reply in that batch reach the subscription before the
    call returns, and every message arrives, in order (a real bridge cannot
    be made to put them in one TCP segment)."""

    async def script(peer: Peer) -> None:
        bridge = FakeBridge()
        while True:
            obj = json.loads(await peer.recv())
            if obj.get("op") != "call_service":
                continue
            if obj["service"].startswith("/rosapi/"):
                await bridge._rosapi(peer, obj)
                continue
            reply = {"op": "service_response", "service": obj["service"], "result": True}
            frames = [publish("/chatter", str(i)) for i in range(3)]
            values = {"success": True, "message": "set"}  # whole, as a bridge sends it
            frames.append(json.dumps({**reply, "values": values, "id": obj["id"]}))
            frames += [publish("/chatter", str(i)) for i in range(3, 5)]
            for frame in frames:
                peer.proto.send_text(frame.encode())
            await peer.send_raw(b"".join(peer.proto.data_to_send()))  # one write

    async with (
        scripted_server(script, subprotocols=()) as url,
        rmb.connect(url, protocol="rosbridge", options=options()) as robot,
        robot.subscribe("/chatter", buffer=10) as sub,
    ):
        await robot.call_service("/rosapi/get_time", {}, timeout=2)  # subscribed by now
        answer = await robot.call_service("/set_flag", {"data": True}, timeout=2)
        assert answer == SetBool.Response(success=True, message="set")
        assert sub.stats.received >= 3
        got = await first_messages(sub, 5)
        assert [m.data.data for m in got] == ["0", "1", "2", "3", "4"]
