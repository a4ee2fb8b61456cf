"""A call cut off by a lost connection names the cause, on every transport.

A service call, an action goal or a parameter operation in flight when the
peer dies raises :class:`rmb.NotConnected` saying the connection was lost,
at the loss: not a timeout, not a server error, and not after the
reconnection. Each test kills the real peer while the request is held at
the server (a handler that never answers), with a 60 s timeout on the call
that must not be what ends it."""

from __future__ import annotations

import os
import signal
import threading
import uuid
from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import FAST, fast_options, wait_until
from _util import zenoh_options as zoptions

pytest_plugins = ["peers.ros_fixtures"]

CALL_TIMEOUT = 60.0
"""The calls' own timeout: far past the loss, so it cannot be what ends them."""
PROMPT = 20.0
"""The test's bound on the wait for the call to end (a third of the call's timeout)."""
LOST = "connection was lost"

POLICIES = {"no-reconnect": None, "reconnect": FAST}


async def cut_off(
    start: Callable[[], Awaitable[Any]], held: Callable[[], bool], kill: Callable[[], Any]
) -> BaseException:
    """Run ``start`` (the request), wait until ``held`` (the peer holds it),
    ``kill`` the peer; return what the request raised, within
    :data:`PROMPT` seconds."""
    outcome: list[BaseException] = []

    async def request() -> None:
        try:
            await start()
        except Exception as exc:
            outcome.append(exc)
        else:  # pragma: no cover - the assertion below says it
            outcome.append(AssertionError("the request succeeded"))

    async with anyio.create_task_group() as tg:
        tg.start_soon(request)
        await wait_until(held, timeout=15.0, what="the request held at the peer")
        await anyio.to_thread.run_sync(kill)
        with anyio.fail_after(PROMPT):
            await wait_until(lambda: bool(outcome), timeout=PROMPT, what="the request to end")
    return outcome[0]


def assert_lost(error: BaseException) -> None:
    assert isinstance(error, rmb.NotConnected), repr(error)
    assert LOST in str(error), str(error)


# -- zenoh ------------------------------------------------------------------------------------
@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_zenoh_a_call_cut_off_by_the_router_death_raises_not_connected(
    sdk: Callable[..., Any], zenoh_domain: int, policy: str
) -> None:
    from peers.zenoh_router import ZenohRouter

    with ZenohRouter() as router:
        server = sdk("service", "--name", "/held", "--hang", router=router)
        opts = zoptions(
            zenoh_domain,
            connect_timeout=2.0,
            keepalive_interval=0.2,
            keepalive_timeout=1.0,
            reconnect=POLICIES[policy],
        )
        async with rmb.connect(router.locator, options=opts) as client:
            await wait_until(
                lambda: any(s.name == "/held" for s in client.services),
                timeout=15.0,
                what="the service",
            )
            error = await cut_off(
                lambda: client.call_service("/held", {"data": True}, timeout=CALL_TIMEOUT),
                lambda: bool(server.records()),
                router.kill,
            )
    assert_lost(error)


def zenoh_opts(domain: int, policy: str) -> rmb.ClientOptions:
    """The keep-alive declares a router missing for 1 s lost."""
    return zoptions(
        domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=1.0,
        service_timeout=CALL_TIMEOUT,
        reconnect=POLICIES[policy],
    )


@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_zenoh_a_parameter_get_cut_off_by_the_router_death_raises_not_connected(
    sdk: Callable[..., Any], zenoh_domain: int, policy: str
) -> None:
    """``/held_node``'s get_parameters service holds every request."""
    from peers.zenoh_router import ZenohRouter

    with ZenohRouter() as router:
        server = sdk(
            "service",
            "--type",
            "rcl_interfaces/srv/GetParameters",
            "--name",
            "/held_node/get_parameters",
            "--node",
            "held_node",
            "--hang",
            router=router,
        )
        async with rmb.connect(router.locator, options=zenoh_opts(zenoh_domain, policy)) as client:
            await wait_until(
                lambda: any(s.name == "/held_node/get_parameters" for s in client.services),
                timeout=15.0,
                what="the parameter service",
            )
            error = await cut_off(
                lambda: client.get_parameters(["/held_node:speed"], timeout=CALL_TIMEOUT),
                lambda: bool(server.records()),
                router.kill,
            )
    assert_lost(error)


@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_zenoh_a_goal_cut_off_by_the_router_death_raises_not_connected(
    sdk: Callable[..., Any], zenoh_domain: int, ros_share: Any, policy: str
) -> None:
    """A goal of 500 steps of 0.1 s is running when the router dies: its
    ``result()`` raises ``ActionGoalLost``, a ``NotConnected`` (and an
    ``ActionGoalError`` whose reason is ``"disconnected"``)."""
    from peers.zenoh_router import ZenohRouter

    fib = "test_msgs/action/Fibonacci"
    with ZenohRouter() as router:
        sdk("action", "--name", "/fibonacci", "--step", "0.1", router=router)
        async with rmb.connect(router.locator, options=zenoh_opts(zenoh_domain, policy)) as client:
            client.register_type(
                fib, (ros_share / f"{fib}.action").read_text(), encoding="ros2action"
            )
            await wait_until(
                lambda: any(s.name == "/fibonacci/_action/cancel_goal" for s in client.services),
                timeout=15.0,
                what="the action server",
            )
            async with client.send_action_goal("/fibonacci", fib, {"order": 500}) as goal:
                await goal.accepted()
                error = await cut_off(goal.result, lambda: True, router.kill)
                assert goal.state == "failed"
    assert_lost(error)
    assert isinstance(error, rmb.ActionGoalLost)
    assert isinstance(error, rmb.ActionGoalError)
    assert error.reason == "disconnected"
    assert "/fibonacci" in str(error)


# -- rosbridge --------------------------------------------------------------------------------
@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_rosbridge_a_call_cut_off_by_the_bridge_death_raises_not_connected(
    ros_graph: Any, rosbridge_factory: Callable[..., Any], policy: str
) -> None:
    """A ROS service of the graph holds the call; the bridge is killed
    (SIGKILL) while it waits for the answer."""
    service = f"/held_{uuid.uuid4().hex[:8]}"
    await anyio.to_thread.run_sync(ros_graph.command, {"cmd": "hold", "service": service})
    bridge = await anyio.to_thread.run_sync(rosbridge_factory)
    try:
        opts = rmb.ClientOptions(
            connect_timeout=5.0,
            discovery_interval=0.5,
            keepalive_interval=0.5,
            keepalive_timeout=1.0,
            reconnect=POLICIES[policy],
        )
        async with rmb.connect(bridge.url, protocol="rosbridge", options=opts) as client:
            await wait_until(
                lambda: any(s.name == service for s in client.services),
                timeout=15.0,
                what="the held service at the bridge",
            )

            def held() -> bool:
                return bool(ros_graph.command({"cmd": "held", "service": service}))

            error = await cut_off(
                lambda: client.call_service(service, {}, timeout=CALL_TIMEOUT),
                held,
                lambda: os.kill(bridge.pid, signal.SIGKILL),
            )
    finally:
        await anyio.to_thread.run_sync(ros_graph.command, {"cmd": "release", "service": service})
        await anyio.to_thread.run_sync(bridge.stop)
    assert_lost(error)


# -- foxglove ---------------------------------------------------------------------------------
@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_foxglove_a_call_cut_off_by_the_server_stop_raises_not_connected(
    policy: str,
) -> None:
    """The Foxglove SDK server's service handler holds the call; the server
    is stopped while the client waits for the answer."""
    from peers.foxglove_sdk import SdkServer, ros2_service

    called = threading.Event()
    release = threading.Event()

    def handler(_request: Any) -> bytes:
        called.set()
        release.wait(120.0)
        return b""

    service = ros2_service(
        "/held", "std_srvs/srv/Trigger", "", "bool success\nstring message", handler
    )
    server = SdkServer(services=[service])
    try:
        opts = fast_options(
            keepalive_interval=0.5, keepalive_timeout=1.0, reconnect=POLICIES[policy]
        )
        async with rmb.connect(server.url, options=opts) as client:
            error = await cut_off(
                lambda: client.call_service("/held", {}, timeout=CALL_TIMEOUT),
                called.is_set,
                server.server.stop,
            )
    finally:
        release.set()
        server.stop()
    assert_lost(error)


@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_foxglove_a_parameter_get_cut_off_by_the_server_stop_raises_not_connected(
    policy: str,
) -> None:
    """The server's get-parameters callback holds the request."""
    from peers.foxglove_sdk import SdkServer, _Listener

    called = threading.Event()
    release = threading.Event()

    class Holding(_Listener):
        def on_get_parameters(
            self, client: Any, param_names: list[str], request_id: str | None = None
        ) -> list[Any]:
            called.set()
            release.wait(20.0)
            return []

    server = SdkServer(listener=Holding, parameters={"speed": 0.5})
    try:
        opts = fast_options(
            keepalive_interval=0.5, keepalive_timeout=1.0, reconnect=POLICIES[policy]
        )
        async with rmb.connect(server.url, options=opts) as client:
            error = await cut_off(
                lambda: client.get_parameters(["speed"], timeout=CALL_TIMEOUT),
                called.is_set,
                server.server.stop,
            )
    finally:
        release.set()
        server.stop()
    assert_lost(error)
