"""``Client.subscribe(topic, decode=False)`` against each transport's real
peer: every message arrives as the wire's bytes (a ``memoryview``), the
codec is never called for one (a spy on the decoding step counts zero; over
Foxglove a channel whose schema the codec cannot parse still yields no
``decode_error``), and ``stats.received`` counts every frame."""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import pytest
from foxglove import Schema

import ros_mobile_bridge as rmb
from _util import take, wait_until
from peers.foxglove_sdk import SdkServer, string_msg
from peers.rosbridge import RosBridge
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import CodecRegistry
from ros_mobile_bridge.flow import _subscription
from ros_mobile_bridge.interfaces.std_msgs.msg import String

pytest_plugins = ["peers.ros_fixtures"]

STRING = "std_msgs/msg/String"


@pytest.fixture
def decodes(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """The topics of every message whose decoder was called: each frame a
    subscription's queue is offered carries a counting wrapper of its
    decoder (the decoding step calls it, wherever it runs)."""
    seen: list[str] = []
    original = _subscription.FrameQueue.offer

    def spy(self: Any, frame: Any) -> None:
        decode = frame.decode
        if decode is not None:

            def counted(payload: memoryview, topic: str = frame.topic) -> Any:
                seen.append(topic)
                return decode(payload)

            frame.decode = counted
        original(self, frame)

    monkeypatch.setattr(_subscription.FrameQueue, "offer", spy)
    return seen


def check_raw(got: list[rmb.Message], sub: rmb.Subscription) -> None:
    for msg in got:
        assert isinstance(msg.data, memoryview)
        assert msg.decode_error is None
        assert msg.byte_size == msg.data.nbytes > 0
    stats = sub.stats
    assert stats.decode_failures == 0
    assert stats.delivered == len(got)
    assert stats.received >= len(got)


async def test_foxglove_raw_messages_are_never_decoded(
    server: SdkServer, decodes: list[str]
) -> None:
    good = server.channel("/good", STRING)
    bad_schema = server.raw_channel(
        "/bad_schema",
        encoding="cdr",
        schema=Schema(name="x/msg/Y", encoding="ros2msg", data=b"this is { not a msg"),
    )
    options = rmb.ClientOptions(advertise_settle=0.0, connect_timeout=5.0)
    async with rmb.connect(server.url, options=options) as robot:
        async with (
            robot.subscribe("/good", decode=False, adaptive=False) as sub,
            robot.subscribe("/bad_schema", decode=False, adaptive=False) as sub2,
        ):
            await wait_until(lambda: {"/good", "/bad_schema"} <= set(server.subscribed()))
            for i in range(50):
                good.log(string_msg(f"n {i}"))
                bad_schema.log(b"\x00\x01\x00\x00" + bytes([i]))
            got = await take(sub, 50)
            got2 = await take(sub2, 50)
    check_raw(got, sub)
    check_raw(got2, sub2)
    assert [bytes(m.data) for m in got] == [string_msg(f"n {i}") for i in range(50)]
    assert [bytes(m.data)[-1] for m in got2] == list(range(50))
    assert {m.schema_name for m in got} == {STRING}
    assert {m.sequence for m in got} == {None}  # Foxglove carries none
    assert sub.stats.received == sub2.stats.received == 50
    assert decodes == []


async def test_rosbridge_raw_messages_are_the_publish_text(
    rosbridge: RosBridge, decodes: list[str]
) -> None:
    options = rmb.ClientOptions(connect_timeout=10.0, reconnect=None)
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options) as robot,
        robot.subscribe("/counter", decode=False, adaptive=False) as sub,
    ):
        got = await take(sub, 20)
    check_raw(got, sub)
    ops = [json.loads(bytes(m.data)) for m in got]
    assert {op["op"] for op in ops} == {"publish"}
    counts = [op["msg"]["data"] for op in ops]
    assert counts == list(range(counts[0], counts[0] + 20))  # in order, none lost
    assert decodes == []


async def test_zenoh_raw_messages_are_the_cdr_payload(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, decodes: list[str]
) -> None:
    sdk("talker", "--rate", "100")
    options = rmb.ClientOptions(domain_id=zenoh_domain)
    async with (
        rmb.connect(zenoh_router.locator, options=options) as robot,
        robot.subscribe("/chatter", decode=False, adaptive=False) as sub,
    ):
        got = await take(sub, 20)
    check_raw(got, sub)
    decode = CodecRegistry().decoder(STRING, "cdr")
    numbers = [int(decode(m.data).data.split()[1]) for m in got]
    assert numbers == list(range(numbers[0], numbers[0] + 20))
    # rmw_zenoh's attachment: the publisher's sequence number and clock
    sequences = [m.sequence for m in got]
    assert sequences == numbers, sequences  # the sdk counts both from 0
    assert all(m.log_time_ns is not None and m.log_time_ns <= m.receive_time_ns for m in got)
    assert {m.schema_name for m in got} == {STRING}
    assert decodes == []


async def test_decoded_subscriptions_still_go_through_the_decoder(
    server: SdkServer, decodes: list[str]
) -> None:
    """The spy sees what it should (so the tests above cannot pass blind)."""
    good = server.channel("/good", STRING)
    options = rmb.ClientOptions(advertise_settle=0.0, connect_timeout=5.0)
    async with rmb.connect(server.url, options=options) as robot:
        async with robot.subscribe("/good", adaptive=False) as sub:
            await wait_until(lambda: "/good" in server.subscribed())
            for i in range(5):
                good.log(string_msg(f"n {i}"))
            got = await take(sub, 5)
    assert [m.data for m in got] == [String(data=f"n {i}") for i in range(5)]
    assert decodes == ["/good"] * 5


async def test_decode_must_be_a_bool(server: SdkServer) -> None:
    options = rmb.ClientOptions(advertise_settle=0.0, connect_timeout=5.0)
    async with rmb.connect(server.url, options=options) as robot:
        with pytest.raises(TypeError, match="decode must be a bool"):
            robot.subscribe("/good", decode="no")  # type: ignore[arg-type]
