"""watch_parameters over rosbridge: the nodes' ``/parameter_events``, through
rosbridge_server_rs to the real ROS 2 graph (``peers.ros_graph_node``, whose
rclpy node ``/rmb_params`` publishes a ``rcl_interfaces/msg/ParameterEvent``
on every change).

Another client of ours sets the values (``/rosapi/set_param``); the watcher
sees each change of a watched name, nothing of the others, nothing after it
stops watching; a user subscription to ``/parameter_events`` keeps its
messages while a watch lives and after it ends; events that are not
``ParameterEvent``s are counted, not fatal; the watch survives a reconnect."""

from __future__ import annotations

import itertools
from collections.abc import AsyncIterator, Iterator
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import rosbridge_options as options
from _util import wait_until
from peers.ros_env import PeerEnv
from peers.rosbridge import RosBridge, RosGraph

pytest_plugins = ["peers.ros_fixtures"]

EVENT = "rcl_interfaces/msg/ParameterEvent"
SPEED = "/rmb_params:speed"
LABEL = "/rmb_params:label"
_values = itertools.count(1)


def fresh() -> float:
    """A speed no earlier set made (the session's graph is shared)."""
    return 100.0 + next(_values) / 4


async def next_update(updates: AsyncIterator[dict[str, Any]]) -> dict[str, Any]:
    with anyio.fail_after(10):
        return await updates.__anext__()


def subscribed(client: rmb.Client) -> bool:
    return bool(client._conn.adapter.parameters.parameter_events_subscribed)  # type: ignore[attr-defined]


async def first_update(setter: rmb.Client, updates: AsyncIterator[dict[str, Any]]) -> Any:
    """Set the speed until the watcher sees a change (the bridge's new ROS
    subscription matches the node's publisher some time after it is made);
    the update seen. (A reader task: cancelling a wait for the next update
    would end the iterator.)"""
    got: list[dict[str, Any]] = []
    async with anyio.create_task_group() as tg:

        async def read() -> None:
            got.append(await updates.__anext__())

        tg.start_soon(read)
        with anyio.fail_after(20):
            while not got:
                await setter.set_parameters({SPEED: fresh()})
                with anyio.move_on_after(0.5):
                    while not got:
                        await anyio.sleep(0.02)
    return got[0]


async def until_watched(setter: rmb.Client, updates: AsyncIterator[dict[str, Any]]) -> float:
    """Set fresh speeds until the watch delivers one of them (the bridge takes
    a ``subscribe`` that changes the topic's encoding some time after it is
    sent: an event before that may come in the old encoding, or not at all);
    the speed delivered. Updates of earlier values are skipped."""
    sent: list[float] = []
    got: list[float] = []
    async with anyio.create_task_group() as tg:

        async def read() -> None:  # (cancelling a wait would end the iterator)
            while True:
                update = await updates.__anext__()
                if update.get(SPEED) in sent:
                    got.append(update[SPEED])
                    return

        tg.start_soon(read)
        with anyio.fail_after(20):
            while not got:
                sent.append(fresh())
                await setter.set_parameters({SPEED: sent[-1]})
                with anyio.move_on_after(0.5):
                    while not got:
                        await anyio.sleep(0.02)
    return got[0]


def speed_of(message: rmb.Message) -> float | None:
    """The new speed of a ``/parameter_events`` message of ``/rmb_params``, if any."""
    event = message.data
    changed = event.changed_parameters
    if event.node == "/rmb_params" and changed:
        return float(changed[0].value.double_value)
    return None


async def until_heard(setter: rmb.Client, sub: rmb.Subscription) -> float:
    """Set fresh speeds until the user's ``/parameter_events`` subscription
    ``sub`` delivers one of them (the bridge takes its ``subscribe`` some time
    after it is sent); the speed delivered."""
    sent: list[float] = []
    got: list[float] = []
    async with anyio.create_task_group() as tg:

        async def read() -> None:
            async for message in sub:
                speed = speed_of(message)
                if speed is not None and speed in sent:
                    got.append(speed)
                    return

        tg.start_soon(read)
        with anyio.fail_after(20):
            while not got:
                sent.append(fresh())
                await setter.set_parameters({SPEED: sent[-1]})
                with anyio.move_on_after(0.5):
                    while not got:
                        await anyio.sleep(0.02)
    return got[0]


async def restore(setter: rmb.Client) -> None:
    await setter.set_parameters({SPEED: 0.5, LABEL: "demo"})


async def test_a_watcher_sees_the_changes_another_client_makes(rosbridge: RosBridge) -> None:
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as watcher,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as setter,
    ):
        try:
            assert not subscribed(watcher)
            async with watcher.watch_parameters([SPEED]) as updates:
                assert subscribed(watcher)
                got = await first_update(setter, updates)
                assert list(got) == [SPEED]
                assert isinstance(got[SPEED], float)
                # a change of another parameter of the node is not delivered ...
                await setter.set_parameters({LABEL: "watched-not"})
                # ... the next watched change is (events arrive in order)
                speed = fresh()
                await setter.set_parameters({SPEED: speed})
                assert await next_update(updates) == {SPEED: speed}
                assert LABEL not in watcher._router.parameters.value
                # a second watch of the same name shares the subscription
                async with watcher.watch_parameters([SPEED]) as again:
                    assert await next_update(again) == {SPEED: speed}  # the newest known
                assert subscribed(watcher)
            # nothing is watched: the subscription is gone
            assert not subscribed(watcher)
            await setter.set_parameters({SPEED: fresh()})
            async with watcher.watch_parameters([LABEL]) as labels:
                label = await first_label(setter, labels)
                assert label.startswith("label ")
            # the speed set while nothing was watched never arrived
            assert watcher._router.parameters.value[SPEED] == speed
            assert watcher.rejections == {}
        finally:
            await restore(setter)


async def first_label(setter: rmb.Client, updates: AsyncIterator[dict[str, Any]]) -> str:
    got: list[dict[str, Any]] = []
    async with anyio.create_task_group() as tg:

        async def read() -> None:
            got.append(await updates.__anext__())

        tg.start_soon(read)
        with anyio.fail_after(20):
            while not got:
                await setter.set_parameters({LABEL: f"label {next(_values)}"})
                with anyio.move_on_after(0.5):
                    while not got:
                        await anyio.sleep(0.02)
    assert list(got[0]) == [LABEL]
    return str(got[0][LABEL])


async def test_a_name_that_is_not_node_colon_param_is_refused(rosbridge: RosBridge) -> None:
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as client:
        with pytest.raises(ValueError, match="/node:param"):
            async with client.watch_parameters(["speed"]):
                pass
        assert not subscribed(client)


@pytest.mark.parametrize("compression", [None, "cbor"])
async def test_a_user_subscription_to_parameter_events_lives_beside_the_watch(
    rosbridge: RosBridge, compression: str | None
) -> None:
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as client,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as setter,
    ):

        async def user_sees(sub: rmb.Subscription, value: float) -> None:
            with anyio.fail_after(10):
                async for message in sub:
                    event = message.data
                    changed = event.changed_parameters
                    if (
                        event.node == "/rmb_params"
                        and changed
                        and changed[0].value.double_value == value
                    ):
                        return

        try:
            async with client.subscribe(
                "/parameter_events", schema=EVENT, compression=compression
            ) as sub:
                # the user's subscription first, then a watch beside it
                async with client.watch_parameters([SPEED]) as updates:
                    got = await first_update(setter, updates)
                    await user_sees(sub, got[SPEED])
                    speed = fresh()
                    await setter.set_parameters({SPEED: speed})
                    assert await next_update(updates) == {SPEED: speed}
                    await user_sees(sub, speed)
                # the watch ended: the user's messages keep coming, decoded
                assert not subscribed(client)
                speed = fresh()
                await setter.set_parameters({SPEED: speed})
                await user_sees(sub, speed)
            # a watch first, the user's subscription comes and goes
            async with client.watch_parameters([SPEED]) as updates:
                await first_update(setter, updates)
                async with client.subscribe(
                    "/parameter_events", schema=EVENT, compression=compression
                ) as sub:
                    # the user's subscription reaches the bridge: both hear it
                    # then, the watch each value set meanwhile, in order
                    heard = await until_heard(setter, sub)
                    with anyio.fail_after(10):
                        while await next_update(updates) != {SPEED: heard}:
                            pass
                    speed = fresh()
                    await setter.set_parameters({SPEED: speed})
                    assert await next_update(updates) == {SPEED: speed}
                    await user_sees(sub, speed)
                speed = fresh()
                await setter.set_parameters({SPEED: speed})
                assert await next_update(updates) == {SPEED: speed}
            assert client.rejections == {}
        finally:
            await restore(setter)


async def test_undecodable_cbor_raw_events_are_counted_and_json_comes_back(
    rosbridge: RosBridge,
) -> None:
    # rosbridge_server_rs 0.1.6 sends ParameterEvent cbor-raw bytes that do
    # not decode (8 bytes past the message): with the user's cbor-raw
    # subscription the watch gets those, counts them and goes on; once the
    # user's subscription ends the watch asks for JSON again and decodes
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as client,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as setter,
    ):
        try:
            async with client.watch_parameters([SPEED]) as updates:
                async with client.subscribe(
                    "/parameter_events", schema=EVENT, compression="cbor-raw"
                ):
                    with anyio.fail_after(20):
                        while not client.rejections.get("decode"):
                            await setter.set_parameters({SPEED: fresh()})
                            await anyio.sleep(0.3)
                assert set(client.rejections) == {"decode"}
                # the watch's own subscribe (JSON) reaches the bridge: a value
                # set after it is decoded and delivered
                await until_watched(setter, updates)
        finally:
            await restore(setter)


async def test_events_that_are_not_parameter_events_are_counted_not_fatal(
    rosbridge: RosBridge,
) -> None:
    # another client publishes on /parameter_events: a real peer can send an
    # event without a node name
    good = {
        "node": "/robot",
        "changed_parameters": [{"name": "gain", "value": {"type": 3, "double_value": 0.75}}],
        "deleted_parameters": [{"name": "old"}, {"name": "unwatched"}],
        "new_parameters": [{"name": "other", "value": {"type": 2, "integer_value": 1}}],
    }
    async with (
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as client,
        rmb.connect(rosbridge.url, protocol="rosbridge", options=options()) as rogue,
        client.watch_parameters(["/robot:gain", "/robot:old"]) as updates,
    ):
        seen: list[dict[str, Any]] = []
        async with anyio.create_task_group() as tg:

            async def read() -> None:
                seen.append(await updates.__anext__())

            tg.start_soon(read)
            with anyio.fail_after(20):
                while not seen:  # until the bridge's subscription hears the publisher
                    await rogue.publish("/parameter_events", EVENT, {"node": ""})
                    await rogue.publish("/parameter_events", EVENT, good)
                    await anyio.sleep(0.5)
        # a deleted parameter is reported as None, as over Foxglove and Zenoh
        assert seen[0] == {"/robot:gain": 0.75, "/robot:old": None}
        # the publisher is matched now: both of the next two arrive, in order
        before = client.rejections.get("malformed", 0)
        await rogue.publish("/parameter_events", EVENT, {"node": ""})
        good["changed_parameters"][0]["value"]["double_value"] = 1.5
        await rogue.publish("/parameter_events", EVENT, good)
        with anyio.fail_after(10):
            async for update in updates:
                if update["/robot:gain"] == 1.5:
                    break
        assert client.rejections.get("malformed", 0) == before + 1
        assert set(client.rejections) == {"malformed"}
        # still reading: a user subscription works as before
        async with client.subscribe("/chatter") as sub:
            with anyio.fail_after(10):
                message = await sub.__anext__()
            assert message.data.data.startswith("hello ")


@pytest.fixture
def own_graph(ros_peer_env: PeerEnv) -> Iterator[RosGraph]:
    """A graph on a domain of its own. Bridges stopped and restarted must not
    share the session's graph: each serves the /rosapi services over ROS,
    and a rosbridge_server_rs 0.1.6 that answers a request of a bridge that
    died meanwhile exits ("client will not receive response"), taking the
    session's bridge down with it."""
    graph = RosGraph.start(ros_peer_env)
    try:
        yield graph
    finally:
        graph.stop()


async def test_the_watch_is_restored_after_a_reconnect(
    ros_peer_env: PeerEnv, own_graph: RosGraph
) -> None:
    def start_bridge(port: int | None = None) -> RosBridge:
        bridge = RosBridge.start(ros_peer_env, own_graph.domain_id, port=port)
        bridges.append(bridge)
        return bridge

    bridges: list[RosBridge] = []
    bridge = await anyio.to_thread.run_sync(start_bridge)
    port = bridge.port
    policy = rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.5)
    seen: list[dict[str, Any]] = []
    try:
        async with (
            rmb.connect(
                bridge.url, protocol="rosbridge", options=options(reconnect=policy)
            ) as watcher,
            watcher.watch_parameters([SPEED]) as updates,
            anyio.create_task_group() as tg,
        ):

            async def consume() -> None:
                async for update in updates:
                    seen.append(update)

            tg.start_soon(consume)

            async def set_until_seen(n: int) -> None:
                async with rmb.connect(
                    bridge.url, protocol="rosbridge", options=options()
                ) as setter:
                    with anyio.fail_after(20):
                        while len(seen) < n:
                            await setter.set_parameters({SPEED: fresh()})
                            await anyio.sleep(0.3)

            await set_until_seen(1)
            first = watcher._conn.adapter
            await anyio.to_thread.run_sync(bridge.stop)
            await wait_until(lambda: watcher.status == "reconnecting", timeout=15.0)
            bridge = await anyio.to_thread.run_sync(lambda: start_bridge(port))
            await wait_until(lambda: watcher.status == "connected", timeout=30)
            assert watcher._conn.adapter is not first  # a new connection ...
            assert subscribed(watcher)  # ... with the watch restored
            count = len(seen)
            await set_until_seen(count + 1)
            assert isinstance(seen[-1][SPEED], float)
            tg.cancel_scope.cancel()
    finally:
        for started in bridges:
            await anyio.to_thread.run_sync(started.stop)
