"""``rmb record [URL] [TOPIC...] -o FILE [--max-hz HZ] [--duration S]``: the
command-line face of :meth:`Client.record`. Ctrl-C (or the duration) stops
it; the file is finished either way, and a summary of what it holds goes to
stderr."""

from __future__ import annotations

import argparse
import math
import sys

import anyio

from .._client import Client
from .._record import Recording
from ._common import NOTICE_AFTER_S, missing_line, open_robot, warn
from ._verb import Verb

__all__ = ["VERBS"]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _build(p: argparse.ArgumentParser) -> None:
    p.add_argument("-o", "--output", required=True, metavar="FILE", help="the .mcap file to write")
    p.add_argument(
        "--max-hz", type=_positive, default=None, metavar="HZ", help="cap each topic's rate"
    )
    p.add_argument(
        "--duration", type=_positive, default=None, metavar="S", help="stop after S seconds"
    )
    p.add_argument(
        "--cbor-raw",
        action="store_true",
        help="rosbridge: have the bridge send CDR (no JSON re-encoding)",
    )


def _summary(rec: Recording, output: str) -> None:
    stats = rec.stats
    for topic, count in sorted(stats.messages.items()):
        skipped = stats.skipped.get(topic, 0)
        extra = f" ({skipped} skipped)" if skipped else ""
        print(f"  {topic}: {count} messages{extra}", file=sys.stderr)
    print(f"{stats.total} messages, {stats.bytes} bytes of payload in {output}", file=sys.stderr)


async def _notice_if_silent(robot: Client, rec: Recording, topic: str) -> None:
    """The notice ``echo`` gives: a named topic that has recorded nothing
    after a few seconds and that the robot does not list (a misspelling)."""
    await anyio.sleep(NOTICE_AFTER_S)
    if rec.stats.messages.get(topic, 0) or topic in {t.name for t in robot.topics}:
        return
    warn(
        f"{topic} has not appeared (still recording): "
        + missing_line("topic", topic, [t.name for t in robot.topics])
    )


async def _record(ns: argparse.Namespace) -> int:
    """Record until ``--duration`` passes or the command is stopped."""
    topics: list[str] | None = list(ns.topic) or None
    async with open_robot(ns) as robot:
        recording = robot.record(
            ns.output,
            topics=topics,
            max_hz=ns.max_hz,
            compression="cbor-raw" if ns.cbor_raw else None,
        )
        held: list[Recording] = []
        try:
            async with recording as rec:
                held.append(rec)
                what = ", ".join(topics) if topics else "every topic"
                print(f"recording {what} to {ns.output} (Ctrl-C stops)", file=sys.stderr)
                async with anyio.create_task_group() as tg:
                    for topic in topics or ():
                        tg.start_soon(_notice_if_silent, robot, rec, topic)
                    if ns.duration is not None:
                        await anyio.sleep(ns.duration)
                    else:
                        await anyio.sleep_forever()
                    tg.cancel_scope.cancel()
        finally:
            if held:  # the file is finished: say what it holds
                _summary(held[0], ns.output)
    return 0


VERBS = [
    Verb(
        ("record",),
        "record topics to an MCAP file (every topic when none is named; Ctrl-C stops, "
        "the file is complete either way)",
        ("TOPIC*",),
        _build,
        _record,
    ),
]
