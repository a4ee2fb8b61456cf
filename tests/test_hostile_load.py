"""Load and process faults from the hostile server (trio-websocket in its
own process, ``peers.hostile``): a flood into a slow consumer, a server
killed mid-call and mid-goal, a kill and restart on the same port, and
connect/leave churn (issue 8, part 4). Every test runs on asyncio and trio
and prints the figure it measured.

The flood lasts ``HOSTILE_FLOOD_SECONDS`` (default 4: the consumer is 10x
over its capacity from the first frame, and the control publish goes out 1 s
in, 2.7 s before its end); the churn makes ``HOSTILE_CHURN_CYCLES`` connections (default 30: a
task, thread or descriptor left per cycle shows as 30). Soak lengths:

    HOSTILE_FLOOD_SECONDS=60 python -m pytest tests/test_hostile_load.py -k flood -s
    HOSTILE_CHURN_CYCLES=1000 python -m pytest tests/test_hostile_load.py -k cycles -s
"""

from __future__ import annotations

import os
import threading
import time

import anyio
import pytest

import ros_mobile_bridge as rmb
from _hostile import WIRE, fd_count, options, rss_bytes, task_count
from _util import wait_until
from peers.hostile import HostileServer

PROTOCOLS = pytest.mark.parametrize("protocol", ["foxglove", "rosbridge"])
FLOOD_SECONDS = float(os.environ.get("HOSTILE_FLOOD_SECONDS", "4"))
CHURN_CYCLES = int(os.environ.get("HOSTILE_CHURN_CYCLES", "30"))


@pytest.mark.timeout(FLOOD_SECONDS * 3 + 60)
async def test_flood_into_a_slow_consumer_stays_bounded_and_control_still_leaves() -> None:
    """2 kHz of 10 kB frames into a consumer taking 5 ms per message (10x
    what it can take): memory stays bounded, every frame is accounted for,
    and a control publish made during the flood reaches the server."""
    samples: list[int] = []
    with HostileServer.start("flood", hz=2000, size=10_000, seconds=FLOOD_SECONDS) as server:
        with anyio.fail_after(FLOOD_SECONDS + 60):
            async with rmb.connect(server.url, protocol="foxglove-ws", options=options()) as robot:
                base = rss_bytes()
                async with robot.subscribe("/blob") as sub:

                    async def consume() -> None:
                        async for _ in sub:
                            await anyio.sleep(0.005)

                    async def sample() -> None:
                        while True:
                            samples.append(rss_bytes())
                            await anyio.sleep(0.1)

                    async with anyio.create_task_group() as tg:
                        tg.start_soon(consume)
                        tg.start_soon(sample)
                        await wait_until(lambda: server.events("flood_start"), timeout=10)
                        await anyio.sleep(min(2.0, FLOOD_SECONDS / 3))
                        with anyio.fail_after(5):
                            await robot.publish(
                                "/cmd_vel",
                                "geometry_msgs/msg/Twist",
                                {"linear": {"x": 0.1}},
                                priority="control",
                            )
                        control_sent = time.time()
                        await wait_until(
                            lambda: server.events("flood_done"),
                            timeout=FLOOD_SECONDS + 30,
                            what="the end of the flood",
                        )
                        tg.cancel_scope.cancel()
                    stats = sub.stats
                    queued = len(sub._queue)
                    assert robot.status == "connected"
        done = server.events("flood_done")[0]
        advertised = [e for e in server.received("advertise") if "/cmd_vel" in e["text"]]
        published = [e for e in server.received() if e["kind"] == "binary" and e["opcode"] == "01"]
    peak = max(samples) - base
    print(
        f"\nflood {done['sent']} frames in {done['seconds']:.1f} s"
        f" ({done['sent'] / done['seconds']:.0f}/s offered): received {stats.received},"
        f" delivered {stats.delivered}, dropped throttle {stats.dropped_throttle}"
        f" overflow {stats.dropped_overflow} breaker {stats.dropped_breaker}"
        f" conflated {stats.dropped_conflated}, queued {queued};"
        f" RSS base {base / 1e6:.0f} MB, peak growth {peak / 1e6:.1f} MB"
    )
    drops = (
        stats.dropped_throttle
        + stats.dropped_overflow
        + stats.dropped_breaker
        + stats.dropped_conflated
    )
    assert stats.received == stats.delivered + drops + queued
    assert drops > 0  # it was an overload
    assert stats.delivered < stats.received
    # the control publish went out during the flood, as client message data
    # on the channel the client advertised for /cmd_vel
    assert advertised
    assert published and published[0]["t"] < done["t"], (published, control_sent)
    assert peak < 150e6, f"RSS grew {peak / 1e6:.0f} MB"


# -- a server killed with requests pending ------------------------------------------------


async def test_server_killed_during_a_service_call_fails_the_call() -> None:
    with HostileServer.start("rosbridge_hang") as server:
        async with rmb.connect(server.url, protocol="rosbridge", options=options()) as robot:

            async def kill() -> None:
                await wait_until(lambda: server.events("call"), what="the call")
                server.kill()

            async with anyio.create_task_group() as tg:
                tg.start_soon(kill)
                start = time.monotonic()
                with anyio.fail_after(10), pytest.raises(rmb.NotConnected) as caught:
                    await robot.call_service("/set_flag", {"data": True}, timeout=30)
            print(f"\ncall failed {time.monotonic() - start:.2f} s after it was made")
    assert "the connection was lost" in str(caught.value), str(caught.value)


async def test_server_killed_during_an_action_goal_fails_the_goal() -> None:
    with HostileServer.start("rosbridge_hang") as server:
        async with rmb.connect(server.url, protocol="rosbridge", options=options()) as robot:
            async with robot.send_action_goal(
                "/fibonacci", "test_msgs/action/Fibonacci", {"order": 5}
            ) as goal:
                await wait_until(lambda: server.events("goal"), what="the goal")
                server.kill()
                with anyio.fail_after(10), pytest.raises(rmb.ActionGoalError) as caught:
                    await goal.result()
    assert caught.value.reason == "disconnected"
    assert goal.state == "failed"


# -- kill and restart on the same port ----------------------------------------------------


@PROTOCOLS
async def test_kill_and_restart_on_the_same_port_restores_the_subscription(
    protocol: str,
) -> None:
    arrivals: list[tuple[float, str]] = []
    server = HostileServer.start("chatter", protocol=protocol, hz=50)
    try:
        opts = options(reconnect=rmb.ReconnectPolicy())
        with anyio.fail_after(60):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=opts) as robot:
                async with robot.subscribe("/chatter") as sub:

                    async def consume() -> None:
                        async for msg in sub:
                            arrivals.append((time.monotonic(), msg.data.data))

                    async with anyio.create_task_group() as tg:
                        tg.start_soon(consume)
                        await wait_until(lambda: len(arrivals) >= 3, what="first messages")
                        server.kill()
                        await wait_until(lambda: robot.status != "connected", what="the loss")
                        await anyio.sleep(1.0)
                        restarted = time.monotonic()
                        server = server.restart("chatter", protocol=protocol, hz=50)
                        await wait_until(
                            lambda: arrivals[-1][0] > restarted,
                            timeout=30,
                            what="a message after the restart",
                        )
                        tg.cancel_scope.cancel()
                    assert robot.status == "connected"
    finally:
        server.stop()
        server.log_path.unlink(missing_ok=True)
    first = next(t for t, _ in arrivals if t > restarted)
    print(f"\nrestart ({protocol}): first message {first - restarted:.2f} s after the restart")
    assert first - restarted < 15


# -- churn ----------------------------------------------------------------------------------


def counts() -> tuple[int, int, int]:
    return task_count(), threading.active_count(), fd_count()


@PROTOCOLS
async def test_connect_leave_cycles_leave_no_task_thread_or_fd(protocol: str) -> None:
    with HostileServer.start("chatter", protocol=protocol, hz=50) as server:

        async def cycle() -> None:
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await sub.__anext__()

        with anyio.fail_after(120):
            await cycle()  # warm-up: whatever is created once and kept
            await anyio.sleep(0.2)  # (a settle: a baseline taken sooner is only higher)
            before = counts()
            start = time.monotonic()
            for _ in range(CHURN_CYCLES):
                await cycle()
            took = time.monotonic() - start
            # the last cycle's tasks and sockets end some time after it;
            # decoders are built in anyio's / trio's worker threads, which
            # stay pooled while idle for up to 10 s: a pooled idle worker is
            # not a leak, one that never goes away is
            with anyio.move_on_after(15):
                while not all(now <= then for now, then in zip(counts(), before, strict=True)):
                    await anyio.sleep(0.05)
            after = counts()
        connects = len(server.events("connect"))
    print(
        f"\nchurn ({protocol}): {CHURN_CYCLES} cycles in {took:.1f} s;"
        f" tasks/threads/fds {before} -> {after}"
    )
    assert connects == CHURN_CYCLES + 1
    assert after[0] <= before[0], f"tasks {before[0]} -> {after[0]}"
    assert after[1] <= before[1], f"threads {before[1]} -> {after[1]}"
    assert after[2] <= before[2], f"file descriptors {before[2]} -> {after[2]}"
