"""``bytes_received`` (per subscription and per connection) and the
``save_bandwidth`` mode over rosbridge (rosbridge_server_rs on a real ROS 2
graph) and Zenoh (zenoh-ros2-sdk talker through a zenoh router), on asyncio
and trio. rosbridge does not pause (it already gets ``max_hz`` as
``throttle_rate``); on Zenoh the subscriber pauses as on Foxglove.
The Foxglove side is in ``test_save_bandwidth.py``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest

import ros_mobile_bridge as rmb
from _util import take, wait_until
from peers.rosbridge import RosBridge

pytest_plugins = ["peers.ros_fixtures"]


def check_bytes(
    client: rmb.Client, sub: rmb.Subscription, got: list[rmb.Message], *, framed: bool
) -> None:
    stats = sub.stats
    conn = client.stats()
    # every frame routed is counted (the delivered ones at least); the
    # connection read them all, and more over a WebSocket (framing, other
    # ops); over Zenoh it counts the samples' payloads
    assert stats.bytes_received >= sum(m.byte_size for m in got) > 0
    assert stats.received >= len(got)
    if framed:
        assert conn.bytes_received > stats.bytes_received
    else:
        assert conn.bytes_received >= stats.bytes_received
    assert conn.messages_received >= stats.received
    assert stats.dropped_replay == 0


async def test_rosbridge_counts_bytes_and_accepts_the_mode_as_a_no_op(
    rosbridge: RosBridge,
) -> None:
    opts = rmb.ClientOptions(connect_timeout=10.0, teardown_timeout=3.0, reconnect=None)
    async with rmb.connect(rosbridge.url, protocol="rosbridge", options=opts) as client:
        async with client.subscribe("/counter", max_hz=10, save_bandwidth=True) as sub:
            got = await take(sub, 4, timeout=20)
            check_bytes(client, sub, got, framed=True)
        # the same throttle_rate as without the mode: the stream keeps
        # coming and nothing is skipped as a replay
        values = [m.data.data for m in got]
        assert values == sorted(values) and len(set(values)) == 4


async def test_zenoh_pauses_the_subscriber_between_deliveries(
    sdk: Callable[..., Any], zenoh_router: Any, zenoh_domain: int
) -> None:
    """With the mode the subscriber is undeclared after each message taken
    and declared again when the next is due, so the router stops
    forwarding in between: a 100 Hz talker at ``max_hz=5`` costs about one
    sample per delivery, where without the mode every sample comes."""
    pytest.importorskip("zenoh_ros2_sdk")
    sdk("talker", "--rate", "100")
    opts = rmb.ClientOptions(domain_id=zenoh_domain)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        await wait_until(
            lambda: any(t.name == "/chatter" for t in client.topics), 15.0, what="the talker"
        )
        async with client.subscribe(
            "/chatter", max_hz=5, save_bandwidth=True, adaptive=False
        ) as saved:
            got = await take(saved, 5, timeout=20)
            check_bytes(client, saved, got, framed=False)
        async with client.subscribe("/chatter", max_hz=5, adaptive=False) as plain:
            await take(plain, 5, timeout=20)
    numbers = [int(m.data.data.split()[1]) for m in got]
    assert numbers == sorted(numbers) and len(set(numbers)) == 5
    mode, every = saved.stats, plain.stats
    # one sample per delivery, and those on their way at each pause (a few
    # on a loaded machine)
    assert mode.received <= 4 * mode.delivered + 2, mode
    # without the mode the cap drops what the router forwarded (~20 a delivery)
    assert every.received >= 5 * every.delivered, every
