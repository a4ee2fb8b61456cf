"""``rmb hz``, ``bw`` and ``delay``: figures of a topic printed every second,
as ``ros2 topic hz / bw / delay`` print them, or one JSON object per line.

``hz`` and ``bw`` count frames on arrival, before any decoding: they
subscribe with ``decode=False`` (the payload is never parsed), no rate cap
and no adaptive throttle, and take the rate from the subscription's
``received`` counter, which counts every frame routed to it before any
filter (plus, over Zenoh, the samples the client's inbox had no room for,
counted before any subscription saw them). Frames the buffer drops while the
printer is busy are therefore still counted; only the gap statistics (min, max, std dev) and the message
sizes come from the frames actually taken. ``delay`` decodes each message
for its ``header.stamp``."""

from __future__ import annotations

import argparse
import itertools
import statistics
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Final

import anyio

from .._types import Message, SubscriptionStats
from ..interfaces._base import RosMessage
from ._common import notice_if_missing, open_robot, out, warn
from ._format import UsageError, json_line
from ._verb import Verb

__all__ = ["VERBS", "ArrivalMeter", "delay_figures"]

_BUFFER: Final = 65536
"""Frames a counting subscription may hold before it drops the oldest
(dropped frames are still counted as arrivals)."""
_BATCH: Final = 4096
_INBOX_DROPS: Final = "backlog_overflow"
"""The rejection a Zenoh client counts for a sample its inbox had no room
for, before any subscription saw it: the command's only subscription is the
one it was for, so it is an arrival too."""


@dataclass
class ArrivalMeter:
    """What ``hz`` and ``bw`` keep: checkpoints of the arrival counter
    ``(monotonic_ns, received)``, one per batch taken, trimmed so they span
    about ``window`` arrivals; and the receive times and sizes of the last
    ``window`` frames taken."""

    window: int
    checkpoints: deque[tuple[int, int]] = field(default_factory=deque)
    stamps: deque[int] = field(init=False)
    sizes: deque[int] = field(init=False)

    def __post_init__(self) -> None:
        self.stamps = deque(maxlen=self.window)
        self.sizes = deque(maxlen=self.window)

    def taken(self, batch: Sequence[Message], received: int, now_ns: int) -> None:
        for msg in batch:
            self.stamps.append(msg.receive_time_ns)
            self.sizes.append(msg.byte_size)
        self.checkpoint(received, now_ns)

    def checkpoint(self, received: int, now_ns: int) -> None:
        points = self.checkpoints
        if points and points[-1][1] == received:
            return
        points.append((now_ns, received))
        while len(points) > 2 and received - points[1][1] >= self.window:
            points.popleft()

    @property
    def arrivals(self) -> int:
        """Frames that arrived between the first and last checkpoint."""
        points = self.checkpoints
        return points[-1][1] - points[0][1] if len(points) >= 2 else 0

    def rate(self) -> float | None:
        """Arrivals per second over the window (None: too few yet)."""
        points = self.checkpoints
        if len(points) < 2:
            return None
        span = (points[-1][0] - points[0][0]) / 1e9
        return self.arrivals / span if span > 0 else None

    def hz(self) -> dict[str, Any] | None:
        rate = self.rate()
        stamps = list(self.stamps)
        if rate is None or len(stamps) < 2:
            return None
        gaps = [(b - a) / 1e9 for a, b in itertools.pairwise(stamps)]
        return {
            "rate_hz": rate,
            "min_s": min(gaps),
            "max_s": max(gaps),
            "std_s": statistics.pstdev(gaps),
            "window": self.arrivals,
        }

    def bw(self) -> dict[str, Any] | None:
        rate = self.rate()
        sizes = list(self.sizes)
        if rate is None or not sizes:
            return None
        mean = statistics.fmean(sizes)
        return {
            "bytes_per_s": mean * rate,
            "messages": self.arrivals,
            "mean_bytes": mean,
            "min_bytes": min(sizes),
            "max_bytes": max(sizes),
        }


def _size(n: float) -> str:
    for unit, scale in (("MB", 1e6), ("KB", 1e3)):
        if n >= scale:
            return f"{n / scale:.2f} {unit}"
    return f"{n:.0f} B"


def _hz_text(f: dict[str, Any]) -> str:
    return (
        f"average rate: {f['rate_hz']:.3f}\n"
        f"\tmin: {f['min_s']:.3f}s max: {f['max_s']:.3f}s std dev: {f['std_s']:.5f}s "
        f"window: {f['window']}"
    )


def _bw_text(f: dict[str, Any]) -> str:
    return (
        f"{_size(f['bytes_per_s'])}/s from {f['messages']} messages\n"
        f"\tMessage size mean: {_size(f['mean_bytes'])} min: {_size(f['min_bytes'])} "
        f"max: {_size(f['max_bytes'])}"
    )


async def _every_second(
    figures: Callable[[], dict[str, Any] | None],
    counter: Callable[[], int],
    text: Callable[[dict[str, Any]], str],
    extra: Callable[[], dict[str, Any]],
    ns: argparse.Namespace,
) -> None:
    """Print the figures once a second while something new arrived ("no new
    messages" once it stops, as ros2 says)."""
    shown = 0
    while True:
        await anyio.sleep(1.0)
        seen = counter()
        if seen == shown:
            if shown:
                if ns.json:
                    out(json_line({"topic": ns.topic, "event": "no new messages", **extra()}))
                else:
                    out("no new messages")
            continue
        shown = seen
        f = figures()
        if f is None:
            continue
        if ns.json:
            out(json_line({"topic": ns.topic, **f, **extra()}))
        else:
            out(text(f))


async def _measure(ns: argparse.Namespace, *, bandwidth: bool) -> int:
    if ns.window < 2:
        raise UsageError(f"--window must be 2 or more, got {ns.window}")
    meter = ArrivalMeter(ns.window)
    async with (
        open_robot(ns, zenoh_backlog=_BUFFER) as robot,
        robot.subscribe(
            ns.topic, decode=False, adaptive=False, buffer=max(_BUFFER, ns.window)
        ) as sub,
    ):

        def queue_stats() -> SubscriptionStats:
            return sub.stats

        def arrivals() -> int:
            return queue_stats().received + robot.rejections.get(_INBOX_DROPS, 0)

        def extra() -> dict[str, Any]:
            s = queue_stats()
            inbox = robot.rejections.get(_INBOX_DROPS, 0)
            dropped = s.dropped_overflow + s.dropped_breaker + inbox
            return {"received": s.received + inbox, "dropped": dropped}

        seen = [0]
        if bandwidth and not ns.json:
            out(f"Subscribed to [{ns.topic}]")
        async with anyio.create_task_group() as tg:
            tg.start_soon(notice_if_missing, robot, ns.topic, seen)
            tg.start_soon(
                _every_second,
                meter.bw if bandwidth else meter.hz,
                lambda: seen[0],
                _bw_text if bandwidth else _hz_text,
                extra,
                ns,
            )
            async for batch in sub.batches(_BATCH):
                received = arrivals()
                seen[0] = received
                meter.taken(batch, received, time.monotonic_ns())
    return 0


async def _hz(ns: argparse.Namespace) -> int:
    return await _measure(ns, bandwidth=False)


async def _bw(ns: argparse.Namespace) -> int:
    return await _measure(ns, bandwidth=True)


# -- delay -------------------------------------------------------------------------------------


def header_stamp_ns(data: Any) -> int | None:
    """``header.stamp`` of a decoded message in nanoseconds, or None when it
    has none."""
    if isinstance(data, RosMessage):
        stamp = getattr(getattr(data, "header", None), "stamp", None)
        sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
        if not isinstance(sec, int) or not isinstance(nanosec, int):
            return None
        return sec * 1_000_000_000 + nanosec
    header = data.get("header") if isinstance(data, dict) else None
    stamp = header.get("stamp") if isinstance(header, dict) else None
    if not isinstance(stamp, dict):
        return None
    sec, nanosec = stamp.get("sec"), stamp.get("nanosec")
    if not isinstance(sec, int) or not isinstance(nanosec, int):
        return None
    return sec * 1_000_000_000 + nanosec


def delay_figures(delays_ns: Sequence[int]) -> dict[str, Any] | None:
    """Mean, min, max and standard deviation (seconds) of the delays."""
    if not delays_ns:
        return None
    seconds = [d / 1e9 for d in delays_ns]
    return {
        "delay_s": statistics.fmean(seconds),
        "min_s": min(seconds),
        "max_s": max(seconds),
        "std_s": statistics.pstdev(seconds),
        "window": len(seconds),
    }


def _delay_text(f: dict[str, Any]) -> str:
    return (
        f"average delay: {f['delay_s']:.3f}\n"
        f"\tmin: {f['min_s']:.3f}s max: {f['max_s']:.3f}s std dev: {f['std_s']:.5f}s "
        f"window: {f['window']}"
    )


async def _delay(ns: argparse.Namespace) -> int:
    if ns.window < 1:
        raise UsageError(f"--window must be 1 or more, got {ns.window}")
    delays: deque[int] = deque(maxlen=ns.window)
    seen = [0]
    async with (
        open_robot(ns) as robot,
        robot.subscribe(ns.topic, adaptive=False) as sub,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(notice_if_missing, robot, ns.topic, seen)
        tg.start_soon(
            _every_second,
            lambda: delay_figures(delays),
            lambda: seen[0],
            _delay_text,
            dict,
            ns,
        )
        async for msg in sub:
            stamp = header_stamp_ns(msg.data)
            if stamp is None:
                reason = msg.decode_error or f"{msg.schema_name} has no header.stamp"
                warn(f"{ns.topic}: cannot measure the delay: {reason}")
                tg.cancel_scope.cancel()
                return 1
            seen[0] += 1
            delays.append(msg.receive_time_ns - stamp)
    return 0


def _options(default: int, what: str) -> Callable[[argparse.ArgumentParser], None]:
    def build(p: argparse.ArgumentParser) -> None:
        p.add_argument(
            "-w",
            "--window",
            type=int,
            default=default,
            metavar="N",
            help=f"measure over the last N {what} (default {default})",
        )
        p.add_argument(
            "--json",
            action="store_true",
            help="one JSON object per line instead of text",
        )

    return build


_HZ = _options(10000, "messages")
_BW = _options(100, "messages")
_DELAY = _options(10000, "messages")

# the verbs' help lines, as the index (_table) has them
_HZ_HELP = "a topic's message rate every second, counted on arrival (--json)"
_BW_HELP = "a topic's bandwidth every second, counted on arrival (--json)"
_DELAY_HELP = "header.stamp against arrival every second, as ros2 topic delay (--json)"

VERBS = [
    Verb(("hz",), _HZ_HELP, ("TOPIC",), _HZ, _hz),
    Verb(("topic", "hz"), _HZ_HELP, ("TOPIC",), _HZ, _hz, hidden=True),
    Verb(("bw",), _BW_HELP, ("TOPIC",), _BW, _bw),
    Verb(("topic", "bw"), _BW_HELP, ("TOPIC",), _BW, _bw, hidden=True),
    Verb(("delay",), _DELAY_HELP, ("TOPIC",), _DELAY, _delay),
    Verb(("topic", "delay"), _DELAY_HELP, ("TOPIC",), _DELAY, _delay, hidden=True),
]
