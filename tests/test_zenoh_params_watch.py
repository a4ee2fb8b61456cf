"""watch_parameters over Zenoh: the nodes' ``/parameter_events``, against a
zenoh-ros2-sdk node (tests/peers/zenoh_sdk_node.py, role ``params``) that
publishes a ``rcl_interfaces/msg/ParameterEvent`` whenever its
``set_parameters`` service changes a value, as rclcpp and rclpy nodes do.

Another client of ours sets the values (through the node's service, over
the same router); the watcher sees each change of a watched name, nothing
of the others, and nothing after it stops watching; garbage on
``/parameter_events`` is counted, not fatal."""

from __future__ import annotations

import contextlib
import json
import time
from collections.abc import AsyncIterator, Iterator
from pathlib import Path
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import routed, unrouted, wait_until
from _util import zenoh_options as options
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.wire import rmw_zenoh as rz

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")
zenoh = pytest.importorskip("zenoh")

EVENT = "rcl_interfaces/msg/ParameterEvent"
SPEED = "/sdk_params:speed"
NAME = "/sdk_params:name"
STRING = "std_msgs/msg/String"


@pytest.fixture
def params_node(zenoh_router: Any, zenoh_domain: int, ros_share: Path) -> Iterator[SdkNode]:
    """The sdk's ``/sdk_params`` node on this test's router and domain."""
    node = SdkNode(zenoh_router.locator, zenoh_domain, ros_share, "params")
    try:
        yield node
    finally:
        node.stop()


@contextlib.contextmanager
def raw_session(locator: str) -> Iterator[Any]:
    """A bare eclipse-zenoh client session to the router at ``locator``."""
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([locator]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()


def data_key(domain: int, topic: str, type_name: str) -> str:
    return rz.format_key(
        rz.TopicKey(domain, topic, type_name, type_hash(CodecRegistry(), type_name))
    )


def attachment(seq: int) -> bytes:
    return rz.encode_attachment(seq, time.time_ns(), bytes(16))


def cdr(type_name: str, value: dict[str, Any]) -> bytes:
    return bytes(CodecRegistry().encoder(type_name, "cdr")(value))


async def next_update(updates: AsyncIterator[dict[str, Any]]) -> dict[str, Any]:
    with anyio.fail_after(10):
        return await updates.__anext__()


async def services_seen(client: rmb.Client) -> None:
    await wait_until(
        lambda: sum(s.name.startswith("/sdk_params/") for s in client.services) == 3, timeout=15.0
    )


def subscribed(client: rmb.Client) -> bool:
    return bool(client._conn.adapter.parameters.parameter_events_subscribed)  # type: ignore[attr-defined]


def test_the_peer_publishes_the_official_event_type(params_node: SdkNode) -> None:
    # the sdk's hash of ParameterEvent is ours: its events reach our key
    assert params_node.hashes[EVENT] == type_hash(CodecRegistry(), EVENT)


async def test_a_watcher_sees_the_changes_another_client_makes(
    params_node: SdkNode, zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    events = data_key(zenoh_domain, "/parameter_events", EVENT)
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as watcher,
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as setter,
    ):
        await services_seen(setter)
        assert not subscribed(watcher)
        async with watcher.watch_parameters([SPEED]) as updates:
            assert subscribed(watcher)
            await routed(raw, events)  # the subscriber's declaration reaches the router
            await setter.set_parameters({SPEED: 1.25})
            assert await next_update(updates) == {SPEED: 1.25}
            # a change of another parameter of the node is not delivered ...
            await setter.set_parameters({NAME: "r2"})
            # ... the next watched change is (events arrive in order)
            await setter.set_parameters({SPEED: 2.5})
            assert await next_update(updates) == {SPEED: 2.5}
            assert NAME not in watcher._router.parameters.value
            # a second watch of the same name shares the subscription
            async with watcher.watch_parameters([SPEED]) as again:
                assert await next_update(again) == {SPEED: 2.5}  # the newest known value
            assert subscribed(watcher)
        # nothing is watched: the internal subscription is gone
        assert not subscribed(watcher)
        await setter.set_parameters({SPEED: 4.0})
        await unrouted(raw, events)  # (its route lingers a while: routed would see it)
        async with watcher.watch_parameters([NAME]) as names:
            await routed(raw, events)
            await setter.set_parameters({NAME: "r3"})
            assert await next_update(names) == {NAME: "r3"}
        # the change made while nothing was watched never arrived
        assert watcher._router.parameters.value[SPEED] == 2.5
        assert watcher.rejections == {}


async def test_a_name_that_is_not_node_colon_param_is_refused(
    zenoh_router: Any, zenoh_domain: int
) -> None:
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        with pytest.raises(ValueError, match="/node:param"):
            async with client.watch_parameters(["speed"]):
                pass
        assert not subscribed(client)


async def test_hostile_parameter_events_are_counted_not_fatal(
    zenoh_router: Any, zenoh_domain: int, raw: Any
) -> None:
    key = data_key(zenoh_domain, "/parameter_events", EVENT)
    good = cdr(
        EVENT,
        {
            "node": "/robot",
            "changed_parameters": [{"name": "gain", "value": {"type": 3, "double_value": 0.75}}],
            "deleted_parameters": [{"name": "old"}, {"name": "unwatched"}],
            "new_parameters": [{"name": "other", "value": {"type": 2, "integer_value": 1}}],
        },
    )
    async with (
        rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
        client.watch_parameters(["/robot:gain", "/robot:old"]) as updates,
    ):
        await routed(raw, key)
        raw.put(key, b"\xff" * 7, attachment=attachment(1))  # garbage CDR
        raw.put(key, good)  # no attachment
        wrong_hash = key.rsplit("/", 1)[0] + f"/RIHS01_{'0' * 64}"
        raw.put(wrong_hash, good, attachment=attachment(2))  # another definition
        raw.put(key, good, attachment=attachment(3))  # and then a good one
        # a deleted parameter is reported as None, as over Foxglove
        assert await next_update(updates) == {"/robot:gain": 0.75, "/robot:old": None}
        assert client.rejections == {"decode": 1, "attachment": 1, "malformed": 1}
        # still reading: a user subscription works as before
        async with client.subscribe("/chatter", schema=STRING) as sub:
            await routed(raw, data_key(zenoh_domain, "/chatter", STRING))
            raw.put(
                data_key(zenoh_domain, "/chatter", STRING),
                cdr(STRING, {"data": "still here"}),
                attachment=attachment(4),
            )
            with anyio.fail_after(10):
                message = await sub.__anext__()
            assert message.data.to_dict() == {"data": "still here"}


async def test_the_watch_is_restored_after_a_router_restart(
    zenoh_domain: int, ros_share: Path
) -> None:
    from peers.zenoh_router import ZenohRouter

    opts = rmb.ClientOptions(
        domain_id=zenoh_domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter().start()
    node = SdkNode(router.locator, zenoh_domain, ros_share, "params")
    seen: list[dict[str, Any]] = []
    try:
        async with (
            rmb.connect(router.locator, options=opts) as watcher,
            watcher.watch_parameters([SPEED]) as updates,
            anyio.create_task_group() as tg,
        ):

            async def consume() -> None:
                async for update in updates:
                    seen.append(update)

            tg.start_soon(consume)
            async with rmb.connect(router.locator, options=options(zenoh_domain)) as setter:
                await services_seen(setter)
                with raw_session(router.locator) as raw:  # the watch's subscriber is declared
                    await routed(raw, data_key(zenoh_domain, "/parameter_events", EVENT))
                await setter.set_parameters({SPEED: 1.0})
                await wait_until(lambda: seen == [{SPEED: 1.0}], timeout=15.0)
            first = watcher._conn.adapter
            router.stop()
            await wait_until(lambda: watcher.status == "reconnecting", timeout=15.0)
            router = ZenohRouter(port=router.port).start()
            await wait_until(lambda: watcher.status == "connected", timeout=20)
            assert watcher._conn.adapter is not first  # a new session ...
            assert subscribed(watcher)  # ... with the watch restored
            async with rmb.connect(router.locator, options=options(zenoh_domain)) as setter:
                # the sdk node's own session reconnects by itself: set new
                # values until one of its events reaches the watcher
                await services_seen(setter)
                value = 2.0
                with anyio.fail_after(20):
                    while len(seen) < 2:
                        await setter.set_parameters({SPEED: value})
                        value += 1.0
                        await anyio.sleep(0.3)
            assert seen[1][SPEED] >= 2.0
            tg.cancel_scope.cancel()
    finally:
        node.stop()
        router.stop()
