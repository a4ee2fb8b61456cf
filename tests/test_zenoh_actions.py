"""Actions over Zenoh against an action server this project did not write: a
``test_msgs/action/Fibonacci`` server assembled from zenoh-ros2-sdk's service
servers and publishers (the ``action`` role of tests/peers/zenoh_sdk_node.py)
with the official Jazzy interface types, through a real eclipse-zenoh router.

The goal's feedback arrives in order and its result with the right sequence
and status; a cancel is honoured; a rejected goal raises ActionGoalError; a
goal whose router goes away fails with a reason instead of waiting."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from peers.zenoh_router import ZenohRouter
from peers.zenoh_sdk_node import SdkNode
from ros_mobile_bridge.codec import CodecRegistry, type_hash

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")

FIB = "test_msgs/action/Fibonacci"
DERIVED = (
    f"{FIB}_SendGoal",
    f"{FIB}_GetResult",
    f"{FIB}_FeedbackMessage",
    "action_msgs/srv/CancelGoal",
    "action_msgs/msg/GoalStatusArray",
)


def fibonacci(order: int) -> list[int]:
    """What the peer's goal of ``order`` ends with (``order + 2`` numbers)."""
    sequence = [0, 1]
    for i in range(1, order + 1):
        sequence.append(sequence[i] + sequence[i - 1])
    return sequence


@pytest.fixture
def action_server(sdk: Callable[..., SdkNode]) -> Callable[..., SdkNode]:
    """The Fibonacci action server on ``/fibonacci`` (an sdk node, stopped with the test)."""

    def start(*args: str, router: ZenohRouter | None = None) -> SdkNode:
        return sdk("action", "--name", "/fibonacci", *args, router=router)

    return start


def official_hash(ros_share: Path, type_name: str) -> str:
    """The RIHS01 hash in the Jazzy wheels' REP-2011 type description."""
    pkg, kind, name = type_name.split("/")
    source = f"{pkg}/{kind}/{name.split('_')[0] if kind == 'action' else name}.json"
    hashes = json.loads((ros_share / source).read_text())["type_hashes"]
    return next(h["hash_string"] for h in hashes if h["type_name"] == type_name)


async def connected(client: rmb.Client, ros_share: Path) -> None:
    """The official Fibonacci.action registered (Zenoh carries no
    definitions), then wait for the server's services."""
    client.register_type(FIB, (ros_share / f"{FIB}.action").read_text(), encoding="ros2action")
    await wait_until(
        lambda: any(s.name == "/fibonacci/_action/cancel_goal" for s in client.services),
        timeout=15.0,
        what="the action server's services",
    )


def test_the_peer_hashes_are_the_official_ones_and_ours(
    action_server: Callable[..., SdkNode], ros_share: Path
) -> None:
    node = action_server()
    ours = CodecRegistry()
    ours.add_schema(FIB, "ros2action", (ros_share / f"{FIB}.action").read_text())
    assert sorted(node.hashes) == sorted(DERIVED)
    for name in DERIVED:
        assert node.hashes[name] == official_hash(ros_share, name) == type_hash(ours, name), name


async def test_feedback_in_order_then_the_result(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    action_server("--step", "0.05")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await connected(client, ros_share)
        assert {s.name: s.type for s in client.services}["/fibonacci/_action/send_goal"] == (
            f"{FIB}_SendGoal"
        )
        async with client.send_action_goal("/fibonacci", FIB, {"order": 8}) as goal:
            await goal.accepted()
            feedback = [list(f.sequence) async for f in goal.feedback]
            outcome = await goal.result()
    assert outcome.status == "succeeded"
    assert list(outcome.result.sequence) == fibonacci(8)
    assert goal.state == "succeeded"
    # newest wins, so some may be skipped, but what came is in order and right
    lengths = [len(f) for f in feedback]
    assert feedback and lengths == sorted(set(lengths))
    assert all(f == fibonacci(8)[: len(f)] for f in feedback)
    assert client.rejections == {}


async def test_a_canceled_goal_ends_canceled(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    action_server("--step", "0.1")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await connected(client, ros_share)
        async with client.send_action_goal("/fibonacci", FIB, {"order": 200}) as goal:
            async for _ in goal.feedback:
                break
            await goal.cancel()
            with anyio.fail_after(10):
                outcome = await goal.result()
    assert outcome.status == "canceled"
    got = list(outcome.result.sequence)
    assert 3 <= len(got) < 202
    assert got == fibonacci(200)[: len(got)]
    assert goal.state == "canceled"


async def test_leaving_the_block_cancels_the_goal_at_the_server(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    action_server("--step", "0.1")
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await connected(client, ros_share)
        async with client.send_action_goal("/fibonacci", FIB, {"order": 200}) as goal:
            await goal.accepted()
        with anyio.fail_after(10):
            outcome = await goal.result()  # the handle still hears the end
    assert outcome.status == "canceled"


async def test_a_rejected_goal_raises_action_goal_error(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    action_server()
    async with rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client:
        await connected(client, ros_share)
        with pytest.raises(rmb.ActionGoalError, match="rejected"):
            async with client.send_action_goal("/fibonacci", FIB, {"order": -1}):
                pytest.fail("a rejected goal was handed out")
        with pytest.raises(rmb.ActionGoalError, match="no action server"):
            async with client.send_action_goal("/elsewhere", FIB, {"order": 1}):
                pytest.fail("a goal for an absent action server was handed out")
        # the server still serves after a rejection
        async with client.send_action_goal("/fibonacci", FIB, {"order": 2}) as goal:
            outcome = await goal.result()
    assert list(outcome.result.sequence) == fibonacci(2)


async def test_a_goal_fails_with_a_reason_when_the_router_goes(
    action_server: Callable[..., SdkNode], zenoh_domain: int, ros_share: Path
) -> None:
    router = ZenohRouter().start()
    try:
        action_server("--step", "0.1", router=router)
        opts = options(
            zenoh_domain,
            keepalive_interval=0.2,
            keepalive_timeout=0.6,
            reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
        )
        async with rmb.connect(router.locator, options=opts) as client:
            await connected(client, ros_share)
            async with client.send_action_goal("/fibonacci", FIB, {"order": 500}) as goal:
                await goal.accepted()
                await anyio.to_thread.run_sync(router.stop)
                with anyio.fail_after(15), pytest.raises(rmb.ActionGoalError) as caught:
                    await goal.result()
        assert caught.value.reason == "disconnected"
        assert goal.state == "failed"
    finally:
        router.stop()


async def test_a_goal_fails_with_a_reason_when_the_action_server_goes(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    server = action_server("--step", "0.1")
    opts = options(zenoh_domain, keepalive_interval=0.2)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await connected(client, ros_share)
        async with client.send_action_goal("/fibonacci", FIB, {"order": 500}) as goal:
            await goal.accepted()
            await anyio.to_thread.run_sync(server.stop)
            with anyio.fail_after(15), pytest.raises(rmb.ActionGoalError) as caught:
                await goal.result()
        assert client.status == "connected"
    assert "the action server is gone" in caught.value.reason
    assert goal.state == "failed"


async def test_unanswered_result_queries_are_asked_again_then_the_goal_fails(
    action_server: Callable[..., SdkNode],
    zenoh_router: ZenohRouter,
    zenoh_domain: int,
    ros_share: Path,
) -> None:
    # the server stays in the graph but ends every get_result query unanswered
    server = action_server("--step", "0.05", "--drop-results")
    opts = options(zenoh_domain, keepalive_interval=0.2)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await connected(client, ros_share)
        async with client.send_action_goal("/fibonacci", FIB, {"order": 3}) as goal:
            with anyio.fail_after(15), pytest.raises(rmb.ActionGoalError) as caught:
                await goal.result()
        assert client.status == "connected"
    assert caught.value.reason == "the action server sent no result (4 queries)"

    def asked() -> list[str]:
        return [m["get_result"] for m in server.messages() if "get_result" in m]

    await wait_until(
        lambda: len(asked()) >= 4, timeout=15.0, what="the server's lines"
    )  # its stdout may lag
    assert len(asked()) == 4
    assert len(set(asked())) == 1
