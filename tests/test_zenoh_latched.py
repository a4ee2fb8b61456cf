"""Latched (transient-local) topics over Zenoh, through a real eclipse-zenoh
router: a subscription that joins late receives what transient-local
publishers keep, in both forms released rmw_zenoh_cpp versions use, and again
after a router restart without duplicates; our ``advertise(latch=True)``
keeps history that rmw_zenoh-form subscribers, a zenoh-ros2-sdk subscriber
and a second client read.

The rmw_zenoh-form publishers and subscribers are raw eclipse-zenoh
stand-ins (``tests/peers/rmw_zenoh_latched.py``): no rmw_zenoh_cpp build is
reachable here, and zenoh-ros2-sdk's publishers keep no history."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from _util import zenoh_options as options
from ros_mobile_bridge.wire import rmw_zenoh as rz

zenoh = pytest.importorskip("zenoh")
from peers.rmw_zenoh_latched import RmwPublisher, RmwSubscriber  # noqa: E402

STRING = "std_msgs/msg/String"
FORMS = ["advanced", "publication_cache"]


class Collector:
    """Every message of a subscription, in a task of its own: ``data``."""

    def __init__(self, sub: rmb.Subscription) -> None:
        self.sub = sub
        self.data: list[str] = []

    async def run(self) -> None:
        async for message in self.sub:
            self.data.append(message.data.data)


async def seen_publisher(client: rmb.Client, topic: str, count: int = 1) -> None:
    await wait_until(
        lambda: sum(1 for q in client._conn.adapter.offered_qos(topic)) >= count,  # type: ignore[attr-defined]
        timeout=15.0,
        what=f"{count} publisher(s) of {topic} in the graph",
    )


@pytest.mark.parametrize("form", FORMS)
async def test_a_late_subscription_receives_the_kept_message_then_live_ones(
    zenoh_router: Any, zenoh_domain: int, form: str
) -> None:
    with RmwPublisher(zenoh_router.locator, zenoh_domain, "/map_meta", depth=1, form=form) as pub:
        pub.publish({"data": "old"})
        pub.publish({"data": "latched"})  # depth 1: only this one is kept
        async with (
            rmb.connect(zenoh_router.locator, options=options(zenoh_domain)) as client,
            anyio.create_task_group() as tg,
        ):
            await seen_publisher(client, "/map_meta")
            async with client.subscribe("/map_meta", schema=STRING) as sub:
                got = Collector(sub)
                tg.start_soon(got.run)
                await wait_until(lambda: got.data, timeout=10.0, what="the kept message")
                assert got.data == ["latched"]
                pub.publish({"data": "live"})
                await wait_until(lambda: len(got.data) == 2, timeout=10.0, what="the live one")
                assert got.data == ["latched", "live"]
                assert sub.stats.dropped_replay == 0
                assert client.rejections == {}
            tg.cancel_scope.cancel()
