"""Closes and stalls no real bridge commits, from the hostile server
(trio-websocket in its own process, ``peers.hostile``): a Close frame with
TCP kept open, a close code and reason the user must see, a peer that stops
reading while the client streams (issue 8, part 2). Every test runs on
asyncio and trio; each prints the detection time it measured."""

from __future__ import annotations

import time

import anyio
import pytest

import ros_mobile_bridge as rmb
from _hostile import WIRE, options, until_data
from _util import wait_until
from peers.hostile import HostileServer

PROTOCOLS = pytest.mark.parametrize("protocol", ["foxglove", "rosbridge"])


@PROTOCOLS
async def test_close_frame_without_tcp_close_is_detected_and_reported(protocol: str) -> None:
    with HostileServer.start("close_hold", protocol=protocol) as server:
        with anyio.fail_after(20):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "before")
                    await wait_until(lambda: server.events("sent_close"), what="the close")
                    sent = server.events("sent_close")[0]["t"]
                    await wait_until(
                        lambda: robot.status != "connected",
                        timeout=10,
                        what="the status to leave 'connected'",
                    )
                    detected = time.time() - sent
                    print(
                        f"\nclose frame, TCP kept open ({protocol}): detected in {detected:.2f} s"
                    )
                    assert robot.status == "error"
    assert "1011" in str(robot.last_error), str(robot.last_error)
    assert "bridge crashed" in str(robot.last_error), str(robot.last_error)


@PROTOCOLS
async def test_close_frame_without_tcp_close_starts_a_reconnect(protocol: str) -> None:
    policy = rmb.ReconnectPolicy(initial_delay=5.0, max_delay=5.0, jitter=0)
    with HostileServer.start("close_hold", protocol=protocol) as server:
        opts = options(reconnect=policy)
        with anyio.fail_after(20):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=opts) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "before")
                    await wait_until(
                        lambda: robot.status != "connected",
                        timeout=10,
                        what="the status to leave 'connected'",
                    )
                    assert robot.status == "reconnecting"
                    assert "1011" in str(robot.last_error), str(robot.last_error)


@PROTOCOLS
async def test_close_code_and_reason_reach_last_error_and_the_subscription(protocol: str) -> None:
    with HostileServer.start("close_1011", protocol=protocol) as server:
        with anyio.fail_after(20):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=options()) as robot:
                async with robot.subscribe("/chatter") as sub:
                    await until_data(sub, "before")
                    with pytest.raises(rmb.NotConnected) as caught:
                        async for _ in sub:
                            pass
    assert "1011 bridge crashed" in str(caught.value), str(caught.value)
    assert "1011 bridge crashed" in str(robot.last_error), str(robot.last_error)


@PROTOCOLS
async def test_control_publish_to_a_peer_that_stopped_reading_raises(protocol: str) -> None:
    opts = options(keepalive_interval=0.5, keepalive_timeout=1.0, zero_twist_on_exit=False)
    backed_up = anyio.Event()
    left_connected: list[float] = []
    with HostileServer.start("stop_reading", protocol=protocol) as server:
        with anyio.fail_after(30):
            async with rmb.connect(server.url, protocol=WIRE[protocol], options=opts) as robot:

                async def stream() -> None:
                    big = {"data": "x" * 65536}
                    try:
                        while True:
                            t = time.monotonic()
                            await robot.publish("/data", "std_msgs/msg/String", big)
                            if time.monotonic() - t > 0.2:  # the outbox is full
                                backed_up.set()
                    except rmb.RosBridgeError:
                        backed_up.set()

                async def watch() -> None:
                    await wait_until(lambda: robot.status != "connected", timeout=25)
                    left_connected.append(time.monotonic())

                stream_start = time.monotonic()
                async with anyio.create_task_group() as tg:
                    tg.start_soon(stream)
                    tg.start_soon(watch)
                    # backed up: the stream wrote for 0.5 s into a socket
                    # nobody reads (several MB), or the outbox is full
                    await wait_until(lambda: server.events("stop_reading"), timeout=10)
                    with anyio.move_on_after(0.5):
                        await backed_up.wait()
                    start = time.monotonic()
                    status_then = robot.status
                    outcome: object = "hung for 8 s"
                    with anyio.move_on_after(8):
                        try:
                            await robot.publish(
                                "/cmd_vel",
                                "geometry_msgs/msg/Twist",
                                {"linear": {"x": 0.3}},
                                priority="control",
                            )
                            outcome = "returned normally"
                        except (rmb.NotConnected, rmb.ConnectError) as exc:
                            outcome = exc
                    raised = time.monotonic() - start
                    assert isinstance(outcome, rmb.RosBridgeError), (
                        f"the control publish {outcome} (made {start - stream_start:.2f} s into"
                        f" the stream, status then {status_then!r}, now {robot.status!r})"
                    )
                    await wait_until(lambda: left_connected, timeout=10)
                    tg.cancel_scope.cancel()
                stopped = server.events("stop_reading")[0]["t"]
                now = time.monotonic() - time.time()
                detected = left_connected[0] - now - stopped
                print(
                    f"\npeer stopped reading ({protocol}): backed up"
                    f" {start - now - stopped:.2f} s after the stop (status {status_then});"
                    f" control publish raised {outcome!r} after {raised:.2f} s;"
                    f" loss detected {detected:.2f} s after the stop"
                )
                # keep-alive 0.5 s + 1 s: "well before 10 s"
                assert detected < 6
