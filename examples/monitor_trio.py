"""Monitor several topics at once on trio: one task per topic in one nursery.

Each task counts its topic's messages and keeps the latest one; the program
stops after ``--seconds``, or as soon as every topic has ``--count`` messages,
and prints each topic's count, rate and latest value (``--json``: one JSON
object, for scripts). A topic that never appears simply stays at zero.

    rmb demo --serve --port 8765 &
    python examples/monitor_trio.py ws://127.0.0.1:8765 /odom /battery /status --seconds 5
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from typing import Any

import trio

import ros_mobile_bridge as rmb
from ros_mobile_bridge.interfaces import RosMessage
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
from ros_mobile_bridge.interfaces.sensor_msgs.msg import BatteryState


@dataclass
class TopicStats:
    count: int = 0
    first: float | None = None
    last: float | None = None
    latest: dict[str, Any] = field(default_factory=dict)

    @property
    def rate_hz(self) -> float:
        if self.first is None or self.last is None or self.count < 2 or self.last == self.first:
            return 0.0
        return (self.count - 1) / (self.last - self.first)


def summary(topic: str, data: Any) -> dict[str, Any]:
    """A few readable fields of the messages the demo robot sends (else the field names)."""
    if isinstance(data, Odometry):
        p = data.pose.pose.position
        return {"x": round(p.x, 3), "y": round(p.y, 3)}
    if isinstance(data, BatteryState):
        return {"percentage": round(data.percentage, 4)}
    if topic == "/status":  # a JSON channel: a dict
        return {"mode": data["mode"], "speed": data["speed"]}
    if isinstance(data, RosMessage):
        return {"fields": list(data.get_fields_and_field_types())[:6]}
    return {"fields": sorted(data)[:6]} if isinstance(data, dict) else {}


async def watch(
    robot: rmb.Client, topic: str, stats: TopicStats, count: int, done: trio.Event
) -> None:
    async with robot.subscribe(topic) as sub:
        async for msg in sub:
            now = trio.current_time()
            stats.first = now if stats.first is None else stats.first
            stats.last = now
            stats.count += 1
            stats.latest = summary(topic, msg.data)
            if stats.count == count:
                done.set()  # keeps counting until every topic is done


async def main(url: str, topics: list[str], seconds: float, count: int, as_json: bool) -> int:
    stats = {topic: TopicStats() for topic in topics}
    async with rmb.cancel_on_signals() as stop, rmb.connect(url) as robot:
        with trio.move_on_after(seconds):
            async with trio.open_nursery() as nursery:
                done = {topic: trio.Event() for topic in topics}
                for topic in topics:
                    nursery.start_soon(watch, robot, topic, stats[topic], count, done[topic])
                if count > 0:
                    for event in done.values():
                        await event.wait()
                    nursery.cancel_scope.cancel()
    if as_json:
        print(
            json.dumps(
                {
                    t: {"count": s.count, "rate_hz": round(s.rate_hz, 2), "latest": s.latest}
                    for t, s in stats.items()
                }
            )
        )
    else:
        for topic, s in stats.items():
            print(f"{topic:<28} {s.count:>6} msgs  {s.rate_hz:6.2f} Hz  {s.latest}")
    return stop.exit_code or 0


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("url")
    parser.add_argument("topics", nargs="*", default=["/odom", "/battery", "/status"])
    parser.add_argument("--seconds", type=float, default=10.0, help="stop after (default 10)")
    parser.add_argument("--count", type=int, default=0, help="stop once every topic has N")
    parser.add_argument("--json", action="store_true", help="print one JSON object")
    a = parser.parse_args()
    sys.exit(trio.run(main, a.url, a.topics, a.seconds, a.count, a.json))
