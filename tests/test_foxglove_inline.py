"""Message data taken where it is read (the Foxglove adapter's inline
handler) against the official Foxglove SDK server: every frame delivered in
order with its time stamps, counted in the subscription's fates, on both
loops; a burst read in one go keeps its order and loses nothing."""

from __future__ import annotations

import anyio

import ros_mobile_bridge as rmb
from _util import fast_options as options
from _util import wait_until, websocket_of
from peers.foxglove_sdk import SdkServer, string_msg


async def test_frames_arriving_one_by_one_are_taken_inline_in_order(server: SdkServer) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/chatter") as sub:
            await wait_until(lambda: sub.state == "active")
            await wait_until(lambda: "/chatter" in server.subscribed())
            before = ws.inline_messages
            got = []
            with anyio.fail_after(10):
                for i in range(20):  # one at a time: each arrives alone
                    chatter.log(string_msg(f"m{i}"), log_time=5000 + i)
                    msg = await sub.__anext__()
                    got.append((msg.data.data, msg.log_time_ns, msg.topic))
            assert got == [(f"m{i}", 5000 + i, "/chatter") for i in range(20)]
            assert ws.inline_messages - before == 20
            stats = sub.stats
            assert (stats.received, stats.delivered, stats.dropped_throttle) == (20, 20, 0)


async def test_a_burst_keeps_its_order_and_every_fate(server: SdkServer) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    n = 1000  # within the server's per-client backlog (1024): it drops nothing
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/chatter", buffer=n) as sub:
            await wait_until(lambda: sub.state == "active")
            await wait_until(lambda: "/chatter" in server.subscribed())
            for i in range(n):
                chatter.log(string_msg(f"b{i}"), log_time=i)
            got = []
            with anyio.fail_after(20):
                async for msg in sub:
                    got.append(msg.log_time_ns)
                    if len(got) == n:
                        break
            assert got == list(range(n))
            stats = sub.stats
            assert (stats.received, stats.delivered, stats.dropped_overflow) == (n, n, 0)


async def test_a_rate_capped_subscription_counts_every_inline_frame(server: SdkServer) -> None:
    chatter = server.channel("/chatter", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/chatter", max_hz=2, adaptive=False) as sub:
            await wait_until(lambda: sub.state == "active")
            await wait_until(lambda: "/chatter" in server.subscribed())
            for i in range(10):
                chatter.log(string_msg(f"c{i}"), log_time=i)
            with anyio.fail_after(10):
                first = await sub.__anext__()  # the first passes the cap at once
                await wait_until(lambda: sub.stats.received == 10)
                last = await sub.__anext__()  # the newest held frame, at the window's end
            assert (first.log_time_ns, last.log_time_ns) == (0, 9)
            stats = sub.stats
            assert (stats.received, stats.delivered, stats.dropped_throttle) == (10, 2, 8)
