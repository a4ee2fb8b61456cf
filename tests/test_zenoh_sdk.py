"""The Zenoh transport against an independent rmw_zenoh implementation:
zenoh-ros2-sdk nodes (tests/peers/zenoh_sdk_node.py) through a real
eclipse-zenoh router, fed the official ROS 2 Jazzy interface files offline.

Its talker reaches our subscription, our publisher reaches its listener, we
call its service server and its nodes' parameter services, a zero Twist
reaches its Twist listener last on normal exit and on cancellation, and a
talker on another domain stays invisible."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")

STRING = "std_msgs/msg/String"
TWIST = "geometry_msgs/msg/Twist"
SCHEMAS = {"/chatter": STRING, "/cmd_vel": TWIST}
# the official hashes (share/<pkg>/<kind>/<Name>.json of the Jazzy wheels)
OFFICIAL = {
    STRING: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    TWIST: "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a",
}


def test_the_sdk_hashes_are_the_official_ones_and_ours(
    sdk: Callable[..., SdkNode],
) -> None:
    talker = sdk("talker", "--count", "1")
    listener = sdk("listener", "--topic", "/cmd_vel", "--type", TWIST)
    assert talker.hashes[STRING] == OFFICIAL[STRING] == type_hash(CodecRegistry(), STRING)
    assert listener.hashes[TWIST] == OFFICIAL[TWIST] == type_hash(CodecRegistry(), TWIST)


async def test_sdk_talker_reaches_our_subscription(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("talker", "--rate", "100")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: any(t.name == "/chatter" for t in client.topics),
            timeout=15.0,
            what="the talker's topic",
        )
        assert [(t.name, t.schema_name) for t in client.topics] == [("/chatter", STRING)]
        async with client.subscribe("/chatter") as sub:
            got: list[int] = []
            with anyio.fail_after(15):
                async for message in sub:
                    assert message.schema_name == STRING
                    assert message.decode_error is None
                    got.append(int(message.data.data.split()[1]))
                    if len(got) == 20:
                        break
        # in order, none skipped (reliable, one publisher)
        assert got == list(range(got[0], got[0] + 20))
        assert client.rejections == {}


async def until_heard(client: rmb.Client, listener: SdkNode, topic: str, probe: Any) -> None:
    """Publish ``probe`` until the SDK listener has one: a sample put before
    the router routes our key to its subscriber is lost (what it received
    after a probe, it received in order)."""
    with anyio.fail_after(15):
        while not listener.messages():
            await client.publish(topic, SCHEMAS[topic], probe)
            with anyio.move_on_after(0.2):
                while not listener.messages():
                    await anyio.sleep(0.02)


async def test_our_publisher_reaches_the_sdk_listener(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    listener = sdk("listener", "--topic", "/chatter", "--type", STRING)
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await client.advertise("/chatter", STRING)
        await until_heard(client, listener, "/chatter", {"data": "probe"})
        for i in range(50):
            await client.publish("/chatter", STRING, {"data": f"from rmb {i}"})

        def ours() -> list[str]:
            return [m["data"] for m in listener.messages() if m["data"] != "probe"]

        await wait_until(
            lambda: len(ours()) >= 50, timeout=15.0, what="50 messages at the listener"
        )
    assert ours() == [f"from rmb {i}" for i in range(50)]


async def test_we_call_the_sdk_service(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("service", "--name", "/sdk_set_bool")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: any(s.name == "/sdk_set_bool" for s in client.services),
            timeout=15.0,
            what="the service",
        )
        assert {s.name: s.type for s in client.services}["/sdk_set_bool"] == "std_srvs/srv/SetBool"
        for value in (True, False, True):
            answer = await client.call_service("/sdk_set_bool", {"data": value}, timeout=5)
            assert answer == SetBool.Response(success=value, message=f"set to {value}")


async def test_parameters_through_the_nodes_parameter_services(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("params")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: sum(s.name.startswith("/sdk_params/") for s in client.services) == 3,
            timeout=15.0,
            what="the parameter services",
        )
        assert await client.list_parameters() == {
            "/sdk_params:enabled": True,
            "/sdk_params:name": "robot",
            "/sdk_params:speed": 0.5,
        }
        assert await client.get_parameters(["/sdk_params:speed"]) == {"/sdk_params:speed": 0.5}
        updated = await client.set_parameters({"/sdk_params:speed": 1.25, "/sdk_params:name": "r2"})
        assert updated == {"/sdk_params:speed": 1.25, "/sdk_params:name": "r2"}
        with pytest.raises(rmb.ParameterError, match="read-only"):
            await client.set_parameters({"/sdk_params:readonly": 1})
        # a node that does not exist: its parameters are not found
        with pytest.raises(rmb.ParameterError, match="'/nobody:x': not found"):
            await client.get_parameters(["/nobody:x"])


@pytest.mark.parametrize("cancel", [False, True], ids=["exit", "cancel"])
async def test_a_zero_twist_reaches_the_sdk_listener_last(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int, cancel: bool
) -> None:
    listener = sdk("listener", "--topic", "/cmd_vel", "--type", TWIST)
    with anyio.CancelScope() as scope:
        async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
            await client.advertise("/cmd_vel", TWIST)
            await until_heard(client, listener, "/cmd_vel", {"linear": {"x": 0.1}})

            def commands() -> list[dict[str, Any]]:  # after the probes
                return [m for m in listener.messages() if m["linear"]["x"] != 0.1]

            for _ in range(10):
                await client.publish(
                    "/cmd_vel", TWIST, {"linear": {"x": 0.4}, "angular": {"z": 0.2}}
                )
            await wait_until(lambda: len(commands()) >= 10, timeout=15.0, what="the commands")
            if cancel:
                scope.cancel()
                await anyio.sleep(5)  # (the cancel: returns at once)
    assert scope.cancelled_caught == cancel
    await wait_until(lambda: len(commands()) >= 11, timeout=15.0, what="the zero Twist")
    await anyio.sleep(0.3)  # nothing may follow it (a window: no event to wait for)
    got = commands()
    assert [m["linear"]["x"] for m in got] == [0.4] * 10 + [0.0]
    assert got[-1]["angular"] == {"x": 0.0, "y": 0.0, "z": 0.0}


async def test_a_talker_on_another_domain_stays_invisible(
    sdk: Callable[..., SdkNode], zenoh_router: Any, zenoh_domain: int
) -> None:
    sdk("talker", "--rate", "100", "--topic", "/chatter", domain=zenoh_domain + 1)
    sdk("talker", "--rate", "100", "--topic", "/near")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await wait_until(
            lambda: any(t.name == "/near" for t in client.topics),
            timeout=15.0,
            what="the near talker",
        )
        await anyio.sleep(0.5)
        assert [t.name for t in client.topics] == ["/near"]
        async with client.subscribe("/chatter", schema=STRING) as sub:
            start = time.monotonic()
            with anyio.move_on_after(1.5):
                async for _ in sub:
                    pytest.fail("a message from another domain arrived")
            assert time.monotonic() - start >= 1.4
