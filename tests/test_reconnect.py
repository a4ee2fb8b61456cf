"""Reconnect against the real Foxglove SDK server, stopped and restarted on
the same port: subscriptions resume, advertisements and parameter watches are
restored, ``async for`` loops keep running, pending calls fail with a reason,
and nothing leaks."""

from __future__ import annotations

import os
import socket
import time
from functools import partial
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import FAST, fast_options, wait_port_free, wait_until
from peers.foxglove_sdk import SdkServer, ros2_service, string_msg

options = partial(
    fast_options,
    connect_timeout=2.0,
    reconnect=FAST,
    keepalive_interval=0.5,
    keepalive_timeout=1.0,
)


def open_fds() -> int:
    return len(os.listdir("/proc/self/fd"))


def blocking_service(called: list[bool]) -> Any:
    def handler(req: Any) -> bytes:
        called.append(True)
        time.sleep(30)  # never answers in time: the call is pending at the outage
        return b""

    return ros2_service(
        "/slow", "std_srvs/srv/Trigger", "", "bool success\nstring message", handler
    )


async def test_subscriptions_advertisements_and_parameter_watches_survive_a_server_restart() -> (
    None
):
    first = SdkServer(parameters={"gain": 1.0})
    port = first.port
    chatter = first.channel("/chatter", "std_msgs/msg/String")
    tasks_before = len(anyio.get_running_tasks())
    fds_before = open_fds()
    got: list[str] = []
    statuses: list[str] = []
    second: SdkServer | None = None
    try:
        async with rmb.connect(first.url, options=options()) as robot:
            async with anyio.create_task_group() as tg:

                async def watch() -> None:
                    async for status in robot.watch_status():
                        statuses.append(status)

                tg.start_soon(watch)
                async with robot.subscribe("/chatter") as sub, robot.watch_parameters(["gain"]):

                    async def consume() -> None:
                        async for msg in sub:  # must keep running across the outage
                            got.append(msg.data.data)

                    tg.start_soon(consume)
                    await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")
                    await wait_until(lambda: "/chatter" in first.subscribed())
                    chatter.log(string_msg("before"))
                    await wait_until(lambda: got == ["before"], what="first message")

                    # the outage
                    first.stop()
                    await wait_until(lambda: robot.status == "reconnecting", what="reconnecting")
                    assert sub.state == "pending"
                    with pytest.raises(rmb.NotConnected, match="reconnecting"):
                        await robot.publish("/cmd_vel", "geometry_msgs/msg/Twist", {})

                    # back, on the same port
                    await wait_port_free(port)
                    second = SdkServer(port=port, parameters={"gain": 2.0})
                    chatter2 = second.channel("/chatter", "std_msgs/msg/String")
                    await wait_until(
                        lambda: robot.status == "connected", timeout=10, what="reconnected"
                    )
                    await wait_until(
                        lambda: sub.state == "active", what="subscription active again"
                    )
                    await wait_until(lambda: "/chatter" in second.subscribed(), what="resubscribed")
                    # restored without the user doing anything
                    assert [a[1] for a in second.recorder.advertised] == ["/cmd_vel"]
                    await wait_until(lambda: "gain" in second.recorder.param_subscribed)
                    chatter2.log(string_msg("after"))
                    await wait_until(
                        lambda: got == ["before", "after"], what="message after reconnect"
                    )
                    assert sub.stats.received == 2  # the counts continue
                    await robot.publish(
                        "/cmd_vel", "geometry_msgs/msg/Twist", {"linear": {"x": 0.1}}
                    )
                    await wait_until(lambda: second.messages("/cmd_vel"))
                tg.cancel_scope.cancel()
        assert statuses[:3] == ["connected", "reconnecting", "connected"]
    finally:
        if second is not None:
            second.stop()
        else:
            first.stop()
    # nothing leaks: the client's tasks and sockets are gone
    assert len(anyio.get_running_tasks()) == tasks_before
    await wait_until(lambda: open_fds() <= fds_before, what="file descriptors back to baseline")


async def test_a_pending_call_fails_with_connection_lost_at_the_outage() -> None:
    called: list[bool] = []
    server = SdkServer(services=[blocking_service(called)])
    try:
        async with rmb.connect(server.url, options=options()) as robot:
            outcome: list[BaseException] = []

            async def call() -> None:
                try:
                    await robot.call_service("/slow", {}, timeout=20)
                except rmb.RosBridgeError as exc:
                    outcome.append(exc)

            async with anyio.create_task_group() as tg:
                tg.start_soon(call)
                await wait_until(lambda: called, what="the request at the server")
                server.server.stop()
                with anyio.fail_after(5):
                    await wait_until(lambda: outcome, what="the call to fail")
            assert isinstance(outcome[0], rmb.NotConnected)
            assert "the connection was lost" in str(outcome[0])
    finally:
        server.stop()


async def test_reconnect_gives_up_after_max_attempts_and_ends_loops_with_an_error() -> None:
    server = SdkServer()
    server.channel("/chatter", "std_msgs/msg/String")
    policy = rmb.ReconnectPolicy(initial_delay=0.01, max_delay=0.02, max_attempts=2)
    try:
        async with rmb.connect(server.url, options=options(reconnect=policy)) as robot:
            async with robot.subscribe("/chatter") as sub:
                server.stop()
                with anyio.fail_after(10), pytest.raises(rmb.NotConnected):
                    async for _ in sub:
                        pass
                assert robot.status == "error"
                assert isinstance(robot.last_error, rmb.ConnectError)
    finally:
        server.stop()


async def test_without_a_policy_a_lost_connection_ends_in_error() -> None:
    server = SdkServer()
    try:
        async with rmb.connect(server.url, options=options(reconnect=None)) as robot:
            server.stop()
            await wait_until(lambda: robot.status == "error", what="error status")
    finally:
        server.stop()


async def test_the_first_connect_is_never_retried() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.monotonic()
    with pytest.raises(rmb.ConnectError):
        async with rmb.connect(f"127.0.0.1:{port}", options=options()):
            pass
    assert time.monotonic() - start < 2
