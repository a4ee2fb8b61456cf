"""``Subscription.batches()``: messages handed over as lists, against the
official Foxglove SDK server. Every message arrives once, in order; a batch
holds what was waiting (never more than ``max_size``, never empty); the end
and cancellation behave as for ``async for msg in sub``."""

from __future__ import annotations

from functools import partial

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.foxglove_sdk import SdkServer, string_msg

TOPIC = "/chatter"


options = partial(rmb.ClientOptions, zero_twist_on_exit=False)


async def subscribed(server: SdkServer) -> None:
    """Until the server has the client's subscription (a message logged
    before it goes to no one)."""
    await wait_until(lambda: TOPIC in server.subscribed(), what="the server has the subscription")


async def test_waiting_messages_come_in_batches_in_order(server: SdkServer) -> None:
    channel = server.channel(TOPIC, "std_msgs/msg/String")
    count = 300
    async with (
        rmb.connect(server.url, options=options()) as robot,
        robot.subscribe(TOPIC, buffer=count, adaptive=False) as sub,
    ):
        await subscribed(server)
        for i in range(count):
            channel.log(string_msg(str(i)))
        await wait_until(lambda: sub.stats.received == count, what="every message received")
        sizes: list[int] = []
        got: list[str] = []
        with anyio.fail_after(10):
            async for batch in sub.batches(max_size=50):
                assert 1 <= len(batch) <= 50
                sizes.append(len(batch))
                got += [msg.data.data for msg in batch]
                if len(got) == count:
                    break
        assert got == [str(i) for i in range(count)]
        assert sizes == [50] * 6  # all were waiting: full batches
        assert sub.stats.delivered == count


async def test_a_batch_waits_for_the_first_message_then_takes_what_is_there(
    server: SdkServer,
) -> None:
    channel = server.channel(TOPIC, "std_msgs/msg/String")
    async with (
        rmb.connect(server.url, options=options()) as robot,
        robot.subscribe(TOPIC, adaptive=False) as sub,
    ):
        await subscribed(server)
        batches = sub.batches()
        with anyio.move_on_after(0.2) as scope:
            await batches.__anext__()  # nothing published: it waits
        assert scope.cancelled_caught
        channel.log(string_msg("only"))
        with anyio.fail_after(5):
            batch = await batches.__anext__()
        assert [m.data.data for m in batch] == ["only"]


async def test_a_cancelled_wait_loses_nothing(server: SdkServer) -> None:
    channel = server.channel(TOPIC, "std_msgs/msg/String")
    async with (
        rmb.connect(server.url, options=options()) as robot,
        robot.subscribe(TOPIC, adaptive=False) as sub,
    ):
        await subscribed(server)
        for _ in range(3):
            with anyio.move_on_after(0.05):
                await sub.batches().__anext__()
        channel.log(string_msg("a"))
        channel.log(string_msg("b"))
        await wait_until(lambda: sub.stats.received == 2)
        with anyio.CancelScope() as scope:
            scope.cancel()
            with pytest.raises(anyio.get_cancelled_exc_class()):
                await sub.batches().__anext__()  # cancelled before taking anything
        with anyio.fail_after(5):
            batch = await sub.batches().__anext__()
        assert [m.data.data for m in batch] == ["a", "b"]


async def test_iteration_ends_after_the_queued_messages(server: SdkServer) -> None:
    channel = server.channel(TOPIC, "std_msgs/msg/String")
    async with (
        rmb.connect(server.url, options=options()) as robot,
        robot.subscribe(TOPIC, adaptive=False) as sub,
    ):
        await subscribed(server)
        channel.log(string_msg("last"))
        await wait_until(lambda: sub.stats.received == 1)
        sub.close()
        with anyio.fail_after(5):
            batches = [[m.data.data for m in b] async for b in sub.batches()]
        assert batches == [["last"]]


async def test_bad_max_size_is_refused_at_once(server: SdkServer) -> None:
    server.channel(TOPIC, "std_msgs/msg/String")
    async with (
        rmb.connect(server.url, options=options()) as robot,
        robot.subscribe(TOPIC) as sub,
    ):
        with pytest.raises(ValueError, match="max_size"):
            sub.batches(max_size=0)
        with pytest.raises(TypeError, match="max_size"):
            sub.batches(max_size=2.5)  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="max_size"):
            sub.batches(max_size=True)
