"""``rmb record URL [topics...] -o FILE [--max-hz HZ] [--duration S]``: the
command-line face of :meth:`Client.record`. ``cli.py`` wires it in with
:func:`add_parser` and runs :func:`run` under its signal handling (Ctrl-C
cancels; the file is finished either way)."""

from __future__ import annotations

import argparse
import math
import sys
from typing import Any

import anyio

from ._connect import connect
from ._options import ClientOptions
from ._record import Recording

__all__ = ["add_parser", "run"]


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value > 0 or math.isinf(value):
        raise argparse.ArgumentTypeError(f"must be a positive number, got {text!r}")
    return value


def add_parser(subparsers: Any) -> None:
    """Add the ``record`` command to ``subparsers`` (what
    ``ArgumentParser.add_subparsers()`` returned). It sets ``run_async`` to
    :func:`run`."""
    p = subparsers.add_parser(
        "record",
        help="record topics to an MCAP file",
        description=(
            "Record what the robot sends to an MCAP file (ROS 2 CDR with full schemas, readable by "
            "Foxglove and the mcap tools). Without topics, every topic is recorded, and those that "
            "appear later. Stops after --duration, or on Ctrl-C; the file is complete either way."
        ),
    )
    p.add_argument("url", help="robot: host, host:port, ws://host:port, wss://..., tcp/host:port")
    p.add_argument("topics", nargs="*", help="topics to record (default: every topic)")
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
    p.add_argument(
        "--protocol", default="auto", choices=("auto", "foxglove-ws", "rosbridge", "zenoh")
    )
    p.add_argument("--timeout", type=_positive, default=10.0, help="connect timeout, seconds")
    p.set_defaults(run_async=run)


def _summary(rec: Recording, output: str) -> None:
    stats = rec.stats
    for topic, count in sorted(stats.messages.items()):
        skipped = stats.skipped.get(topic, 0)
        extra = f" ({skipped} skipped)" if skipped else ""
        print(f"  {topic}: {count} messages{extra}", file=sys.stderr)
    print(f"{stats.total} messages, {stats.bytes} bytes of payload in {output}", file=sys.stderr)


async def run(args: argparse.Namespace) -> int:
    """Record until ``args.duration`` passes or the task is cancelled;
    print a summary (messages per topic) to stderr. Returns 0; raises what
    :func:`connect` and :meth:`Client.record` raise (bad arguments:
    ``ValueError``; connection: ``RosBridgeError``; the file: ``OSError``)."""
    topics: list[str] | None = list(args.topics) or None
    options = ClientOptions(connect_timeout=args.timeout)
    async with connect(args.url, protocol=args.protocol, options=options) as robot:
        recording = robot.record(
            args.output,
            topics=topics,
            max_hz=args.max_hz,
            compression="cbor-raw" if args.cbor_raw else None,
        )
        held: list[Recording] = []
        try:
            async with recording as rec:
                held.append(rec)
                what = ", ".join(topics) if topics else "every topic"
                print(f"recording {what} to {args.output} (Ctrl-C stops)", file=sys.stderr)
                if args.duration is not None:
                    await anyio.sleep(args.duration)
                else:
                    await anyio.sleep_forever()
        finally:
            if held:  # the file is finished: print what it holds
                _summary(held[0], args.output)
    return 0
