"""``bytes_received`` (per subscription and per connection) and the
``save_bandwidth`` mode over rosbridge (rosbridge_server_rs on a real ROS 2
graph) and Zenoh (zenoh-ros2-sdk talker through a zenoh router), on asyncio
and trio. Neither bridge pauses: rosbridge already gets ``max_hz`` as
``throttle_rate``, and on Zenoh the mode is accepted and changes nothing.
The Foxglove side is in ``test_save_bandwidth.py``."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from peers.rosbridge import RosBridge

pytest_plugins = ["peers.ros_fixtures"]


async def take(sub: rmb.Subscription, n: int) -> list[rmb.Message]:
    got: list[rmb.Message] = []
    with anyio.fail_after(20):
        async for msg in sub:
            got.append(msg)
            if len(got) == n:
                break
    return got


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
            got = await take(sub, 4)
            check_bytes(client, sub, got, framed=True)
        # the same throttle_rate as without the mode: the stream keeps
        # coming and nothing is skipped as a replay
        values = [m.data["data"] for m in got]
        assert values == sorted(values) and len(set(values)) == 4


async def test_zenoh_counts_bytes_and_accepts_the_mode_as_a_no_op(
    sdk: Callable[..., Any], zenoh_router: Any, zenoh_domain: int
) -> None:
    pytest.importorskip("zenoh_ros2_sdk")
    sdk("talker", "--rate", "100")
    opts = rmb.ClientOptions(domain_id=zenoh_domain)
    async with rmb.connect(zenoh_router.locator, options=opts) as client:
        with anyio.fail_after(15):
            while not any(t.name == "/chatter" for t in client.topics):
                await anyio.sleep(0.05)
        async with client.subscribe("/chatter", max_hz=50, save_bandwidth=True) as sub:
            got = await take(sub, 5)
            check_bytes(client, sub, got, framed=False)
        async with client.subscribe("/chatter", adaptive=False) as every:
            whole = await take(every, 10)
        numbers = [int(m.data["data"].split()[1]) for m in whole]
        assert numbers == list(range(numbers[0], numbers[0] + 10))  # none skipped
        assert every.stats.bytes_received >= sum(m.byte_size for m in whole)
