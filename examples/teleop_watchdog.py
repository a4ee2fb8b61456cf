"""A teleoperation loop that is safe to interrupt.

Velocity commands go out at control priority (ahead of queued data, newest
value wins). Ctrl-C, an exception or a cancelled scope all leave the
``connect()`` block, whose teardown sends a zero Twist while the socket is
still open. If the network itself is gone, nothing the client does can reach
the robot: the robot must run its own cmd_vel watchdog (the demo robot stops
0.5 s after its last command).

    rmb demo --serve --port 8765 &
    python examples/teleop_watchdog.py ws://127.0.0.1:8765 2.0
"""

from __future__ import annotations

import sys

import anyio

import ros_mobile_bridge as rmb


async def main(url: str, seconds: float) -> None:
    options = rmb.ClientOptions(stop_topics=("/cmd_vel",), teardown_timeout=2.0)
    async with rmb.connect(url, options=options) as robot:
        await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")  # no set-up pause later
        with anyio.move_on_after(seconds):
            while True:
                await robot.publish(
                    "/cmd_vel",
                    "geometry_msgs/msg/Twist",
                    {"linear": {"x": 0.3}, "angular": {"z": 0.5}},
                    priority="control",
                )
                await anyio.sleep(0.05)
    print("stopped: zero Twist sent on teardown")


if __name__ == "__main__":
    url = sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8765"
    anyio.run(main, url, float(sys.argv[2]) if len(sys.argv) > 2 else 2.0)
