"""A fleet of robots in one task group: connect to all, read each one's state,
drive them together, stop them all.

Each robot runs in its own task with its own ``connect()`` block, so each one's
teardown sends its own zero Twist. A robot that cannot be reached (or fails
later) is reported and does not take down the others: its task catches
``rmb.RosBridgeError`` (and ``OSError``) itself. The exit status is 1 when any
robot failed.

    rmb demo --serve --port 8765 &  rmb demo --serve --port 8766 &
    python examples/fleet.py ws://127.0.0.1:8765 ws://127.0.0.1:8766 --seconds 1
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass
from typing import Any

import anyio

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry


@dataclass
class Report:
    url: str
    ok: bool = False
    detail: str = "not started"


async def first(robot: rmb.Client, topic: str, timeout: float = 5.0) -> Any:
    """The next message on ``topic`` (raises ``TimeoutError`` after ``timeout`` seconds)."""
    with anyio.fail_after(timeout):
        async with robot.subscribe(topic) as sub:
            async for msg in sub:
                return msg.data
    raise rmb.NotConnected(f"{topic}: subscription ended")


async def odometry(robot: rmb.Client, timeout: float = 5.0) -> Odometry:
    """The next odometry message (``TimeoutError`` after ``timeout`` seconds)."""
    with anyio.fail_after(timeout):
        async with robot.subscribe("/odom", Odometry) as sub:
            async for msg in sub:
                return msg.data
    raise rmb.NotConnected("/odom: subscription ended")


async def run_robot(url: str, report: Report, seconds: float, speed: float) -> None:
    options = rmb.ClientOptions(
        stop_topics=("/cmd_vel",), connect_timeout=5.0, teardown_timeout=2.0
    )
    try:
        async with rmb.connect(url, options=options) as robot:
            status = await first(robot, "/status")  # a JSON channel: a dict
            with anyio.move_on_after(seconds):
                while True:
                    await robot.publish(
                        "/cmd_vel", Twist(linear=Vector3(x=speed)), priority="control"
                    )
                    await anyio.sleep(0.1)
            x = (await odometry(robot)).pose.pose.position.x
            report.ok = True
            report.detail = f"mode={status['mode']} battery={status['battery_percentage']:.0%}"
            report.detail += f" x={x:.2f}"
        # the block's teardown has sent this robot its zero Twist
    except (rmb.RosBridgeError, OSError, TimeoutError) as exc:
        report.detail = f"FAILED {type(exc).__name__}: {exc}"


async def main(urls: list[str], seconds: float, speed: float) -> int:
    reports = [Report(url) for url in urls]
    async with rmb.cancel_on_signals() as stop, anyio.create_task_group() as tg:
        for report in reports:
            tg.start_soon(run_robot, report.url, report, seconds, speed)
    for report in reports:
        print(f"{report.url}: {'ok ' if report.ok else ''}{report.detail}")
    if stop.exit_code is not None:
        return stop.exit_code
    return 0 if all(r.ok for r in reports) else 1


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("urls", nargs="+")
    parser.add_argument("--seconds", type=float, default=1.0, help="how long to drive")
    parser.add_argument("--speed", type=float, default=0.2, help="linear.x, m/s")
    parser.add_argument("--backend", choices=("asyncio", "trio"), default="asyncio")
    a = parser.parse_args()
    sys.exit(anyio.run(main, a.urls, a.seconds, a.speed, backend=a.backend))
