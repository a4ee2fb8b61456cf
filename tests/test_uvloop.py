"""A whole client on uvloop, as a web backend under uvicorn runs it: uvloop's
transports are not ``asyncio.Transport`` subclasses, and the asyncio stream
reads them directly (its own tests run on uvloop too: test_asyncio_stream.py).
The relay example (test_examples.py) runs under uvicorn, which picks uvloop
whenever it is installed, as the test extras install it."""

from __future__ import annotations

import asyncio
import sys
from collections.abc import Iterator

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import FAST, fast_options, take, wait_port_free, wait_until
from ros_mobile_bridge.demo import DemoRobot

pytestmark = pytest.mark.skipif(sys.platform == "win32", reason="uvloop has no Windows build")


@pytest.fixture
def anyio_backend() -> object:
    pytest.importorskip("uvloop")
    return ("asyncio", {"use_uvloop": True})


@pytest.fixture
def robot() -> Iterator[DemoRobot]:
    """Not conftest's ``robot``: a fresh one per test, at faster rates."""
    with DemoRobot(rate_hz=50.0, camera_hz=10.0) as demo:
        yield demo


async def test_a_client_on_uvloop_subscribes_publishes_and_stops_the_robot(
    robot: DemoRobot,
) -> None:
    import uvloop

    assert isinstance(asyncio.get_running_loop(), uvloop.Loop)
    before = len(robot.received_cmd_vel())
    async with rmb.connect(robot.url, options=fast_options()) as client:
        assert client.status == "connected"
        async with (
            client.subscribe("/odom") as odom,
            client.subscribe("/camera/image/compressed") as camera,
        ):
            assert all(m.topic == "/odom" for m in await take(odom, 5))
            (image,) = await take(camera, 1)
            assert image.byte_size > 0
        await client.publish(
            "/cmd_vel",
            "geometry_msgs/msg/Twist",
            {"linear": {"x": 0.2}},
            priority="control",
        )
        await wait_until(
            lambda: any(c.linear_x == 0.2 for c in robot.received_cmd_vel()[before:]),
            what="the command at the robot",
        )
    # leaving the block sent the zero Twist, last
    await wait_until(
        lambda: robot.received_cmd_vel()[-1].linear_x == 0.0, what="the zero Twist at the robot"
    )
    assert robot.received_cmd_vel()[-1].angular_z == 0.0


async def test_a_client_on_uvloop_reconnects_after_the_server_restarts() -> None:
    with DemoRobot() as first:
        port = first.port
        async with rmb.connect(first.url, options=fast_options(reconnect=FAST)) as client:
            statuses = client.watch_status()
            first.stop()
            with anyio.fail_after(10):
                async for status in statuses:
                    if status == "reconnecting":
                        break
            await wait_port_free(port)
            with DemoRobot(port=port):
                with anyio.fail_after(15):
                    async for status in statuses:
                        if status == "connected":
                            break
                async with client.subscribe("/odom") as odom:
                    assert len(await take(odom, 2)) == 2
