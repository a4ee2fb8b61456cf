"""``rmb record [URL] [TOPIC...] [-o FILE|-] [--overwrite] [--max-hz HZ]
[--duration S]``: the command-line face of :meth:`Client.record`. Ctrl-C (or
the duration) stops it; the file is finished either way, and a summary of
what it holds goes to stderr.

Without ``-o`` the file is named from the local date and time,
``rmb_YYYY_MM_DD-HH_MM_SS.mcap`` in the current directory (ros2 bag record's
``rosbag2_YYYY_MM_DD-HH_MM_SS`` with another prefix: it is one MCAP file, not
a rosbag2 directory). An existing output is refused (exit 1, before
connecting) unless ``--overwrite`` (``-f``) is given. ``-o -`` writes the
MCAP to stdout (refused when stdout is a terminal, exit 2)."""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from typing import IO

import anyio

from .._core._client import Client
from .._core._record import Recording, RecordStats
from ._common import NOTICE_AFTER_S, missing_line, open_robot, warn
from ._verb import Verb

__all__ = ["VERBS", "default_output", "plural"]


def plural(count: int, word: str) -> str:
    """``1 message``, ``2 messages``, ``0 messages``."""
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


def default_output(now: float | None = None) -> str:
    """The output name when ``-o`` is not given: ``rmb_`` and the local
    date and time, as ros2 bag record names its directories."""
    return time.strftime("rmb_%Y_%m_%d-%H_%M_%S.mcap", time.localtime(now))


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def _build(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-o",
        "--output",
        default=None,
        metavar="FILE",
        help="the .mcap file to write, '-' for stdout "
        "(default: rmb_YYYY_MM_DD-HH_MM_SS.mcap, the local time)",
    )
    p.add_argument(
        "-f", "--overwrite", action="store_true", help="replace FILE if it exists (else refused)"
    )
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


def summary_lines(stats: RecordStats, output: str) -> list[str]:
    """What ``rmb record`` prints on stderr when the file is finished: one
    line per topic (written, re-encoded, skipped by reason), then the
    totals."""
    lines = []
    for topic in sorted(set(stats.messages) | set(stats.skipped)):
        notes = []
        if stats.reencoded.get(topic):
            notes.append(f"{stats.reencoded[topic]} re-encoded to CDR")
        for reason, n in sorted(stats.skip_reasons.get(topic, {}).items()):
            notes.append(f"{n} skipped: {reason}")
        extra = f" ({'; '.join(notes)})" if notes else ""
        lines.append(f"  {topic}: {plural(stats.messages.get(topic, 0), 'message')}{extra}")
    for topic, why in sorted(stats.failed.items()):
        lines.append(f"  {topic}: not recorded: {why}")
    skipped = f", {stats.total_skipped} skipped" if stats.total_skipped else ""
    lines.append(
        f"{plural(stats.total, 'message')}{skipped}, {plural(stats.bytes, 'byte')} "
        f"of payload in {output}"
    )
    return lines


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


def _target(ns: argparse.Namespace) -> tuple[str | IO[bytes], str] | int:
    """Where to write and how to name it in messages, or the exit status of
    a refusal (said on stderr)."""
    if ns.output == "-":
        if sys.stdout.isatty():
            warn("not writing binary MCAP to a terminal: redirect stdout, or give -o FILE")
            return 2
        return sys.stdout.buffer, "stdout"
    output = ns.output or default_output()
    if os.path.lexists(output) and not ns.overwrite:
        warn(f"{output} exists; --overwrite (-f) replaces it")
        return 1
    return output, output


async def _record(ns: argparse.Namespace) -> int:
    """Record until ``--duration`` passes or the command is stopped."""
    topics: list[str] | None = list(ns.topic) or None
    target = _target(ns)
    if isinstance(target, int):
        return target
    where, label = target
    async with open_robot(ns) as robot:
        recording = robot.record(
            where,
            topics=topics,
            max_hz=ns.max_hz,
            compression="cbor-raw" if ns.cbor_raw else None,
        )
        held: list[Recording] = []
        try:
            async with recording as rec:
                held.append(rec)
                what = ", ".join(topics) if topics else "every topic"
                print(f"recording {what} to {label} (Ctrl-C stops)", file=sys.stderr)
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
                for line in summary_lines(held[0].stats, label):
                    print(line, file=sys.stderr)
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
