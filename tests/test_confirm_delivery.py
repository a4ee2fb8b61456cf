"""``confirm_delivery()``: a round trip behind what was published, for the
caller who must know that a command reached the server. A publish into a
socket whose peer died or went silent returns normally (TCP cannot tell);
the confirmation is what tells. Against real peers, each made silent with
SIGSTOP (a router or bridge that hangs, the case a write cannot detect),
resumed, and stopped or killed. Over Zenoh it is refused (no round trip
the router alone answers)."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import fast_options, wait_until
from _util import zenoh_options as zoptions
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3

pytest_plugins = ["peers.ros_fixtures"]

SILENT = 1.0
"""How long a confirmation waits on a silent peer before it gives up."""
LONG = 30.0
"""A bound the confirmation from a live peer stays far inside."""


async def silent_then_back(client: rmb.Client, pid: int) -> None:
    """With the peer paused, a control publish still returns and its
    confirmation times out; resumed, the confirmation comes."""
    os.kill(pid, signal.SIGSTOP)
    try:
        await client.publish("/cmd_vel", Twist(linear=Vector3(x=0.2)), priority="control")
        with pytest.raises(rmb.ServiceTimeout):
            await client.confirm_delivery(timeout=SILENT)
    finally:
        os.kill(pid, signal.SIGCONT)
    await client.confirm_delivery(timeout=LONG)


async def test_foxglove_confirmed_publishes_have_reached_the_server_and_a_stopped_server_raises() -> (
    None
):
    from peers.foxglove_sdk import SdkServer

    with SdkServer() as server:
        opts = fast_options(reconnect=None)
        async with rmb.connect(server.url, options=opts) as client:
            for x in (0.1, 0.2, 0.3):
                await client.publish("/cmd_vel", Twist(linear=Vector3(x=x)))  # data: queued
            await client.confirm_delivery(timeout=LONG)
            await wait_until(
                lambda: len(server.messages("/cmd_vel")) >= 3, timeout=LONG, what="the Twists"
            )
            await anyio.to_thread.run_sync(server.server.stop)
            with pytest.raises(rmb.NotConnected):
                await client.confirm_delivery(timeout=LONG)


async def test_zenoh_cannot_confirm_and_says_why(zenoh_router: Any, zenoh_domain: int) -> None:
    """A zenoh put has no acknowledgement, and the session answers a
    liveliness query for its own token itself while the router is silent:
    no round trip proves the router has what was put, so the client says so
    rather than confirm what it cannot know."""
    opts = zoptions(zenoh_domain, connect_timeout=5.0, reconnect=None)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await client.publish("/cmd_vel", Twist(), priority="control")
        with pytest.raises(rmb.NotSupportedError, match="no acknowledgement"):
            await client.confirm_delivery(timeout=LONG)


async def test_rosbridge_a_silent_bridge_is_not_confirmed_then_confirms(
    rosbridge_factory: Callable[..., Any],
) -> None:
    bridge = await anyio.to_thread.run_sync(rosbridge_factory)
    try:
        opts = rmb.ClientOptions(connect_timeout=10.0, keepalive_timeout=LONG, reconnect=None)
        async with rmb.connect(bridge.url, protocol="rosbridge", options=opts) as client:
            await client.publish("/cmd_vel", Twist(), priority="control")
            await client.confirm_delivery(timeout=LONG)
            await silent_then_back(client, bridge.pid)
            os.kill(bridge.pid, signal.SIGKILL)
            with pytest.raises(rmb.NotConnected):
                await client.confirm_delivery(timeout=LONG)
    finally:
        await anyio.to_thread.run_sync(bridge.stop)


async def test_confirm_delivery_checks_its_timeout_at_once() -> None:
    from peers.foxglove_sdk import SdkServer

    with SdkServer() as server:
        async with rmb.connect(server.url, options=fast_options(reconnect=None)) as client:
            with pytest.raises(TypeError):
                await client.confirm_delivery(timeout="soon")  # type: ignore[arg-type]
            with pytest.raises(ValueError, match="positive"):
                await client.confirm_delivery(timeout=-1.0)
