"""``rmb demo``: start the embedded demo robot (served by the official
Foxglove SDK server on 127.0.0.1), drive it in a circle with this library
while printing a live readout, and leave with the zero Twist, showing that
the robot received it last. ``rmb demo --serve`` only serves the robot, for
other tools (and for the other ``rmb`` commands)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from collections.abc import Callable, Mapping
from typing import Any

import anyio

from .. import _connect
from .._options import ClientOptions
from ..interfaces.nav_msgs.msg import Odometry
from ..interfaces.sensor_msgs.msg import BatteryState
from ..interfaces.std_srvs.srv import SetBool
from ._verb import Verb, run_signalled

__all__ = ["VERBS"]


class _Rates:
    def __init__(self) -> None:
        self.counts: dict[str, int] = {}
        self.start = time.monotonic()

    def hit(self, topic: str) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def line(self) -> str:
        elapsed = max(time.monotonic() - self.start, 1e-9)
        return "  ".join(f"{t} {n / elapsed:4.1f}Hz" for t, n in sorted(self.counts.items()))


async def _drive_demo(url: str, seconds: float, out: Callable[[str], None]) -> None:
    """The client session of ``rmb demo`` against the robot at ``url``."""
    options = ClientOptions(connect_timeout=5.0)
    async with _connect.connect(url, options=options) as robot:
        out(
            f"connected to {robot.server_info.name!r} over {robot.protocol} ({robot.server_info.subprotocol})"
        )
        out("topics:   " + ", ".join(f"{t.name} [{t.schema_name}]" for t in robot.topics))
        out("services: " + ", ".join(f"{s.name} [{s.type}]" for s in robot.services))
        params = await robot.list_parameters()
        out(f"parameters: {json.dumps(params, sort_keys=True)}")
        reply = await robot.call_service("/set_led", SetBool.Request(data=True), timeout=5)
        out(f"call /set_led {{data: true}} -> {reply.to_dict()}")
        await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")

        rates = _Rates()
        state: dict[str, Any] = {}

        async def follow(topic: str, max_hz: float | None) -> None:
            async with robot.subscribe(topic, max_hz=max_hz, dispatch="latest") as sub:
                async for msg in sub:
                    rates.hit(topic)
                    state[topic] = msg.data

        async with anyio.create_task_group() as tg:
            for topic, cap in (
                ("/odom", None),
                ("/battery", None),
                ("/camera/image/compressed", None),
                ("/status", None),
            ):
                tg.start_soon(follow, topic, cap)
            out(
                f"driving in a circle for {seconds:g} s (linear.x 0.4 m/s, angular.z 0.8 rad/s) ..."
            )
            deadline = time.monotonic() + seconds
            next_print = 0.0
            while time.monotonic() < deadline:
                await robot.publish(
                    "/cmd_vel",
                    "geometry_msgs/msg/Twist",
                    {"linear": {"x": 0.4}, "angular": {"z": 0.8}},
                    priority="control",
                )
                now = time.monotonic()
                if now >= next_print:
                    next_print = now + 0.5
                    out(_readout(state, rates))
                await anyio.sleep(0.1)
            tg.cancel_scope.cancel()
        out("leaving the session: the teardown sends a zero Twist to /cmd_vel, then closes")


def _readout(state: Mapping[str, Any], rates: _Rates) -> str:
    odom = state.get("/odom")
    pose = "pose: waiting for /odom"
    if isinstance(odom, Odometry):
        p = odom.pose.pose
        q = p.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y**2 + q.z**2))
        pose = f"pose x={p.position.x:+.2f} y={p.position.y:+.2f} yaw={math.degrees(yaw):+6.1f}deg"
    battery = state.get("/battery")
    batt = f"battery {battery.percentage * 100:.1f}%" if isinstance(battery, BatteryState) else ""
    return f"  {pose}  {batt}  | {rates.line()}"


async def _serve_until_signalled(url: str) -> None:
    # said once the signals are ours, so a supervisor may stop us from here on
    print(f"demo robot serving Foxglove WebSocket on {url} (Ctrl-C to stop)", flush=True)
    await anyio.sleep_forever()


def _demo(args: argparse.Namespace) -> int:
    try:
        from ..demo import DemoRobot
    except ImportError as exc:  # the Foxglove SDK is the optional [demo] extra
        print(
            f"rmb demo needs the demo extra: pip install 'ros-mobile-bridge[demo]' ({exc})",
            file=sys.stderr,
        )
        return 2
    robot = DemoRobot(port=args.port)
    robot.start()
    try:
        if args.serve:
            return run_signalled(_serve_until_signalled, robot.url, backend=args.backend)
        print(f"demo robot started on {robot.url}", flush=True)
        code = run_signalled(
            _drive_demo,
            robot.url,
            args.seconds,
            lambda s: print(s, flush=True),
            backend=args.backend,
        )
        if code:
            return code
        # the zero Twist is the last command the robot received
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            log = robot.received_cmd_vel()
            if log and log[-1].linear_x == 0.0 and log[-1].angular_z == 0.0:
                break
            time.sleep(0.02)
        log = robot.received_cmd_vel()
        if not log:
            print("FAIL: the robot received no velocity command", file=sys.stderr)
            return 1
        last = log[-1]
        moving = sum(1 for c in log if c.linear_x or c.angular_z)
        print(
            f"robot received {len(log)} velocity commands ({moving} moving); "
            f"the last one: linear.x={last.linear_x} angular.z={last.angular_z} ({last.encoding})"
        )
        if last.linear_x == 0.0 and last.angular_z == 0.0:
            x, y, _ = robot.pose
            print(f"OK: the zero Twist arrived last; the robot stopped at x={x:+.2f} y={y:+.2f}")
            return 0
        print("FAIL: the last command the robot received was not a zero Twist", file=sys.stderr)
        return 1
    finally:
        robot.stop()


def _build(p: argparse.ArgumentParser) -> None:
    p.add_argument("--serve", action="store_true", help="only serve the robot, for other tools")
    p.add_argument(
        "--port", type=int, default=0, help="port for the robot's server (default: any free)"
    )
    p.add_argument("--seconds", type=float, default=4.0, help="how long to drive (default 4)")


VERBS = [
    Verb(
        ("demo",),
        "run the embedded demo robot and drive it (--serve: only serve it)",
        build=_build,
        run_sync=_demo,
    )
]
