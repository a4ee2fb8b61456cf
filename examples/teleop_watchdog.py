"""A teleoperation loop that is safe to interrupt.

Velocity commands go out at control priority (ahead of queued data, newest
value wins). Ctrl-C, SIGTERM or SIGHUP (``rmb.cancel_on_signals``), an
exception or a cancelled scope all leave the ``connect()`` block, whose
teardown sends a zero Twist while the socket is still open; a second signal
exits at once. If the network itself is gone, nothing the client does can reach
the robot: the robot must run its own cmd_vel watchdog (the demo robot stops
0.5 s after its last command).

    rmb demo --serve --port 8765 &
    python examples/teleop_watchdog.py ws://127.0.0.1:8765 2.0
"""

from __future__ import annotations

import sys

import anyio

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3


async def main(url: str, seconds: float) -> int:
    options = rmb.ClientOptions(stop_topics=("/cmd_vel",), teardown_timeout=2.0)
    async with (
        rmb.cancel_on_signals() as stop,
        rmb.connect(url, options=options) as robot,
    ):
        await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")  # no set-up pause later
        with anyio.move_on_after(seconds):
            while True:
                twist = Twist(linear=Vector3(x=0.3), angular=Vector3(z=0.5))
                await robot.publish("/cmd_vel", twist, priority="control")
                await anyio.sleep(0.05)
    if stop.signal is not None:
        print(f"stopped by {stop.signal.name}: zero Twist sent on teardown")
        return 128 + stop.signal
    print("stopped: zero Twist sent on teardown")
    return 0


if __name__ == "__main__":
    url = sys.argv[1] if len(sys.argv) > 1 else "ws://127.0.0.1:8765"
    sys.exit(anyio.run(main, url, float(sys.argv[2]) if len(sys.argv) > 2 else 2.0))
