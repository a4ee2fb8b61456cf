"""Quick start on asyncio: list topics, read one odometry message, call a
service, drive briefly. Run against the demo robot:

    rmb demo --serve --port 8765 &
    python examples/quickstart_asyncio.py ws://127.0.0.1:8765
"""

from __future__ import annotations

import asyncio
import sys

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.std_srvs.srv import SetBool


async def main(url: str) -> int:
    # Ctrl-C, SIGTERM (timeout, systemd, docker stop) or SIGHUP cancel the
    # block below, so the teardown still sends its zero Twist.
    async with rmb.cancel_on_signals() as stop, rmb.connect(url) as robot:
        print("topics:", [t.name for t in robot.topics])
        async with robot.subscribe("/odom", Odometry, max_hz=10) as sub:
            async for msg in sub:  # msg.data is an Odometry
                position = msg.data.pose.pose.position
                print(f"{msg.topic}: x={position.x:.2f} y={position.y:.2f}")
                break
        reply = await robot.call_service("/set_led", SetBool.Request(data=True), timeout=5)
        print("set_led ->", reply.success, reply.message)  # a SetBool.Response
        for _ in range(5):
            await robot.publish("/cmd_vel", Twist(linear=Vector3(x=0.2)), priority="control")
            await asyncio.sleep(0.1)
    # leaving the block sent a zero Twist to /cmd_vel, then closed the socket
    return stop.exit_code or 0  # 128 + signal when a signal ended it


if __name__ == "__main__":
    sys.exit(asyncio.run(main(sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8765")))
