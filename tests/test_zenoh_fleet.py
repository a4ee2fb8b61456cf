"""A fleet across routers: two eclipse-zenoh routers linked on loopback
(router B's ``connect/endpoints`` names router A), a robot behind each
(zenoh-ros2-sdk nodes: a talker, a service server, an action server), and
one client connected to router A only, as a fleet manager would be.

The client reaches the topics, services and actions of both robots; when
router B goes away (its process killed) the robot behind it leaves the
client's graph while robot A stays, and when router B comes back on the
same port (its robot's nodes reconnect by themselves, as zenoh sessions do)
the robot returns: its topics and services are listed again, the
subscription held all along delivers again, and calls and goals work. Every
wait is on the event itself (the graph, a message, an answer)."""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from peers.zenoh_router import ZenohRouter
from peers.zenoh_sdk_node import SdkNode

pytest_plugins = ["peers.ros_fixtures"]
pytest.importorskip("zenoh_ros2_sdk")

STRING = "std_msgs/msg/String"
SET_BOOL = "std_srvs/srv/SetBool"
FIB = "test_msgs/action/Fibonacci"
ROBOTS = ("alpha", "bravo")
"""Robot alpha behind router A (the client's), bravo behind router B."""


class Fleet:
    """Router A, router B linked to it, and one robot (three sdk nodes)
    behind each; ``restart_b()`` runs router B again on the same port."""

    def __init__(self, domain: int, share: Path) -> None:
        self.domain = domain
        self.share = share
        self.a = ZenohRouter().start()
        self.b = ZenohRouter(settings={"connect/endpoints": [self.a.locator]})
        self.nodes: list[SdkNode] = []
        self.b.start()

    def robot(self, name: str, router: ZenohRouter) -> None:
        """A robot's nodes on ``router``: ``/<name>/chatter`` Strings at 20 Hz,
        ``/<name>/set_bool`` and the ``/<name>/fibonacci`` action."""

        def node(role: str, *args: str) -> None:
            self.nodes.append(SdkNode(router.locator, self.domain, self.share, role, *args))

        node("talker", "--topic", f"/{name}/chatter", "--node", f"{name}_talker", "--rate", "20")
        node("service", "--name", f"/{name}/set_bool", "--node", f"{name}_service")
        node("action", "--name", f"/{name}/fibonacci", "--step", "0.02")

    def close(self) -> None:
        for node in self.nodes:
            node.stop()
        self.b.stop()
        self.a.stop()


@pytest.fixture
def fleet(zenoh_domain: int, ros_share: Path) -> Iterator[Fleet]:
    fleet = Fleet(zenoh_domain, ros_share)
    try:
        fleet.robot("alpha", fleet.a)
        fleet.robot("bravo", fleet.b)
        yield fleet
    finally:
        fleet.close()


def offers(client: rmb.Client, robot: str) -> bool:
    """The client's graph holds every topic and service of ``robot``."""
    topics = {t.name for t in client.topics}
    services = {s.name for s in client.services}
    return {f"/{robot}/chatter", f"/{robot}/fibonacci/_action/status"} <= topics and {
        f"/{robot}/set_bool",
        f"/{robot}/fibonacci/_action/send_goal",
    } <= services


def offers_none_of(client: rmb.Client, robot: str) -> bool:
    """No service of ``robot`` in the client's graph, nor a topic only it
    has: the action's status topic, which the client does not subscribe to
    (``/<robot>/chatter`` stays listed while the client's own subscription
    to it lives)."""
    return f"/{robot}/fibonacci/_action/status" not in {t.name for t in client.topics} and not any(
        s.name.startswith(f"/{robot}/") for s in client.services
    )


async def nodes_of(client: rmb.Client, robot: str) -> list[str]:
    return [name for name in await client.nodes() if name.startswith(f"/{robot}_")]


async def until_nodes(client: rmb.Client, robot: str, expected: list[str]) -> None:
    """Wait until the nodes of ``robot`` in the client's graph are
    ``expected`` (each of a robot's processes has a zenoh session of its
    own, which reconnects on its own schedule)."""
    with anyio.move_on_after(30.0):
        while await nodes_of(client, robot) != expected:
            await anyio.sleep(0.01)
        return
    raise AssertionError(f"{robot}'s nodes: {await nodes_of(client, robot)}, not {expected}")


async def reaches(client: rmb.Client, robot: str) -> None:
    """A service call and a whole goal on ``robot`` answer."""
    reply = await client.call_service(f"/{robot}/set_bool", {"data": True})
    assert (reply.success, reply.message) == (True, "set to True")
    async with client.send_action_goal(f"/{robot}/fibonacci", FIB, {"order": 5}) as goal:
        outcome = await goal.result()
    assert list(outcome.result.sequence) == [0, 1, 1, 2, 3, 5, 8]


async def next_message(sub: rmb.Subscription, after_ns: int = 0, timeout: float = 20.0) -> str:
    """The text of the subscription's next message received after
    ``after_ns`` (wall clock; older ones, queued before, are skipped)."""
    with anyio.fail_after(timeout):
        async for message in sub:
            if (message.log_time_ns or 0) > after_ns:
                return str(message.data.data)
    raise AssertionError("the subscription ended")


async def test_one_client_on_router_a_reaches_both_robots_and_follows_router_b(
    fleet: Fleet, ros_share: Path
) -> None:
    async with rmb.connect(fleet.a.locator, options=options(fleet.domain)) as client:
        client.register_type(FIB, (ros_share / f"{FIB}.action").read_text(), encoding="ros2action")
        await wait_until(
            lambda: offers(client, "alpha") and offers(client, "bravo"),
            timeout=30.0,
            what="both robots' topics and services through router A",
        )
        for robot in ROBOTS:
            await until_nodes(client, robot, [f"/{robot}_service", f"/{robot}_talker"])
        async with (
            client.subscribe("/alpha/chatter", schema=STRING) as alpha,
            client.subscribe("/bravo/chatter", schema=STRING) as bravo,
        ):
            assert (await next_message(alpha)).startswith("hello")
            assert (await next_message(bravo)).startswith("hello")
            for robot in ROBOTS:
                await reaches(client, robot)

            # router B goes: the robot behind it leaves the graph, alpha stays
            fleet.b.stop()
            await wait_until(
                lambda: offers_none_of(client, "bravo"), 30.0, what="bravo to leave the graph"
            )
            await until_nodes(client, "bravo", [])
            assert offers(client, "alpha")
            assert await nodes_of(client, "alpha") == ["/alpha_service", "/alpha_talker"]
            assert client.status == "connected"
            await reaches(client, "alpha")
            with pytest.raises(rmb.ServiceError) as gone:
                await client.call_service("/bravo/set_bool", {"data": True}, timeout=1)
            assert "no server offers this service" in str(gone.value)

            # router B comes back on its port; bravo's nodes reconnect by themselves
            fleet.b.start()
            back, back_ns = time.monotonic(), time.time_ns()
            await wait_until(lambda: offers(client, "bravo"), 30.0, what="bravo to return")
            await until_nodes(client, "bravo", ["/bravo_service", "/bravo_talker"])
            listed = time.monotonic() - back
            # the subscription held all along delivers again (a message received since)
            assert (await next_message(bravo, after_ns=back_ns)).startswith("hello")
            delivered = time.monotonic() - back
            await reaches(client, "bravo")
            assert (await next_message(alpha)).startswith("hello")
    print(f"router B back: bravo listed after {listed:.2f} s, delivering after {delivered:.2f} s")
