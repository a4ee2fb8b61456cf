"""Teleoperation on asyncio: drive a short scripted route while watching odometry.

Each step of the route is re-sent at 10 Hz at control priority (ahead of queued
data, the newest command wins), because a robot's cmd_vel watchdog stops it when
commands stop arriving. A second task follows ``/odom`` with ``dispatch="latest"``
(only the newest pose is kept while the loop is busy). Leaving the ``connect()``
block (end of the route, Ctrl-C, SIGTERM, an error) sends a zero Twist to
``/cmd_vel`` while the socket is still open.

    rmb demo --serve --port 8765 &
    python examples/teleop_asyncio.py ws://127.0.0.1:8765
    python examples/teleop_asyncio.py ws://127.0.0.1:8765 --interactive   # w/a/s/d/x + Enter
"""

from __future__ import annotations

import argparse
import asyncio
import sys
from dataclasses import dataclass

import anyio

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry

TWIST = "geometry_msgs/msg/Twist"
RATE_HZ = 10.0

# (label, linear.x m/s, angular.z rad/s, seconds)
ROUTE: list[tuple[str, float, float, float]] = [
    ("forward", 0.3, 0.0, 0.6),
    ("turn left", 0.1, 0.8, 0.5),
    ("forward", 0.3, 0.0, 0.4),
]
KEYS = {"w": (0.3, 0.0), "s": (-0.3, 0.0), "a": (0.0, 0.8), "d": (0.0, -0.8), "x": (0.0, 0.0)}


@dataclass
class Pose:
    x: float = 0.0
    y: float = 0.0
    messages: int = 0


async def follow_odometry(robot: rmb.Client, pose: Pose) -> None:
    async with robot.subscribe("/odom", Odometry, dispatch="latest") as sub:
        async for msg in sub:
            position = msg.data.pose.pose.position
            pose.x, pose.y = position.x, position.y
            pose.messages += 1


async def send(robot: rmb.Client, linear_x: float, angular_z: float) -> None:
    twist = Twist(linear=Vector3(x=linear_x), angular=Vector3(z=angular_z))
    await robot.publish("/cmd_vel", twist, priority="control")


async def drive_route(robot: rmb.Client, pose: Pose) -> None:
    for label, linear_x, angular_z, seconds in ROUTE:
        for _ in range(round(seconds * RATE_HZ)):
            await send(robot, linear_x, angular_z)
            await asyncio.sleep(1 / RATE_HZ)
        print(
            f"{label:<10} linear={linear_x:+.1f} angular={angular_z:+.1f}  "
            f"odom x={pose.x:.2f} y={pose.y:.2f}"
        )


async def drive_keyboard(robot: rmb.Client, pose: Pose) -> None:
    """Line-based keys (no terminal raw mode); each command repeats until the next key."""
    command = (0.0, 0.0)
    async with anyio.create_task_group() as tg:

        async def repeat() -> None:
            while True:
                await send(robot, *command)
                await asyncio.sleep(1 / RATE_HZ)

        tg.start_soon(repeat)
        print("keys: w/s forward/back, a/d turn, x stop, q quit (then Enter)")
        while True:
            # abandon_on_cancel: Ctrl-C need not wait for Enter (the reading thread is left)
            line = await anyio.to_thread.run_sync(sys.stdin.readline, abandon_on_cancel=True)
            key = line.strip().lower()[:1]
            if not line or key == "q":
                break
            command = KEYS.get(key, command)
            await send(robot, *command)  # at once; repeat() keeps it fresh
            print(f"command {command}  odom x={pose.x:.2f} y={pose.y:.2f}")
        tg.cancel_scope.cancel()


async def main(url: str, interactive: bool) -> int:
    options = rmb.ClientOptions(stop_topics=("/cmd_vel",), teardown_timeout=2.0)
    async with rmb.cancel_on_signals() as stop, rmb.connect(url, options=options) as robot:
        await robot.advertise("/cmd_vel", TWIST)  # no set-up pause on the first command
        pose = Pose()
        # asyncio.TaskGroup needs Python 3.11; anyio's task group runs on asyncio from 3.10.
        async with anyio.create_task_group() as tg:
            tg.start_soon(follow_odometry, robot, pose)
            await (drive_keyboard if interactive else drive_route)(robot, pose)
            tg.cancel_scope.cancel()
        print(f"done after {pose.messages} odometry messages: x={pose.x:.2f} y={pose.y:.2f}")
    print("stopped: zero Twist sent on teardown")
    return stop.exit_code or 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url", nargs="?", default="ws://127.0.0.1:8765")
    parser.add_argument("--interactive", action="store_true", help="drive with w/a/s/d keys")
    args = parser.parse_args()
    sys.exit(asyncio.run(main(args.url, args.interactive)))
