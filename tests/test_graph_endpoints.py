"""``nodes()`` and ``topic_endpoints()`` on rosbridge and Zenoh, against
their real peers (rosbridge_server_rs on a ROS 2 graph, zenoh-ros2-sdk nodes
through an eclipse-zenoh router); Foxglove's connection graph is in
test_foxglove_capabilities.py."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import rosbridge_options, zenoh_options
from peers.rosbridge import RosBridge
from peers.zenoh_sdk_node import SdkNode

pytest_plugins = ["peers.ros_fixtures"]

STRING = "std_msgs/msg/String"


async def endpoints_once(
    ask: Callable[[], Awaitable[rmb.TopicEndpoints]], timeout: float = 15.0
) -> rmb.TopicEndpoints:
    """The first answer naming both a publisher and a subscriber (a graph
    learns of its entities as they are declared); asked again until then."""
    with anyio.fail_after(timeout):
        while True:
            ends = await ask()
            if ends.publishers and ends.subscribers:
                return ends
            await anyio.sleep(0.05)


async def test_rosbridge_endpoints_come_from_rosapi(rosbridge: RosBridge) -> None:
    options = rosbridge_options()
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options) as robot:
        async with robot.subscribe("/chatter"):  # rosbridge subscribes on our behalf
            ends = await endpoints_once(lambda: robot.topic_endpoints("/chatter"))
        assert "/rmb_graph" in ends.publishers
        assert ends.subscribers  # the bridge's own node, however it names it
        assert "/rmb_graph" in await robot.nodes()
        assert await robot.topic_endpoints("/none") == rmb.TopicEndpoints("/none", (), ())


async def test_zenoh_endpoints_name_the_talker_and_the_listener(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    pytest.importorskip("zenoh_ros2_sdk")
    sdk("talker", "--rate", "10")
    sdk("listener", "--topic", "/chatter", "--type", STRING)
    options = zenoh_options(zenoh_domain)
    async with rmb.connect(zenoh_router.locator, options=options) as client:
        ends = await endpoints_once(lambda: client.topic_endpoints("/chatter"))
        assert ends == rmb.TopicEndpoints("/chatter", ("/sdk_talker",), ("/sdk_listener",))
        assert {"/sdk_talker", "/sdk_listener"} <= set(await client.nodes())
        assert await client.topic_endpoints("/none") == rmb.TopicEndpoints("/none", (), ())
