"""The httpx transport against the default transport (stand-alone script).

    .venv/bin/python bench/bench_httpx.py [--backend asyncio|trio|both] [--seconds 1]
        [--reps 5] [--json PATH]

The same Foxglove drain as ``bench_foxglove.py`` (its publisher subprocess,
``bench/_peer.py``, and its ``measure``): the client connects and subscribes,
its event loop is blocked while the server queues a fixed number of
messages, then it receives them all through ``rmb.connect`` + ``async for``
(decoded), with the adaptive throttle and the breaker off so that every
message is delivered whatever the lag. Two clients, interleaved, the same
count each:

* ``default``: ``rmb.connect(url)``, the library's own socket;
* ``httpx``: ``rmb.connect(url, options=ClientOptions(http_client=client))``,
  the upgrade made by an ``httpx.AsyncClient`` and the same WebSocket engine
  reading httpcore's network stream.

Cases: String (99-byte CDR) and Image (640x480 rgb8, 921,652 bytes) drains.
Every message's fate is counted (delivered, dropped for a reason, queued):
the run fails when one vanished or was not delivered. Tables show medians
of msgs/s and client CPU microseconds per message, and httpx / default.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from dataclasses import asdict
from pathlib import Path
from typing import Any, Final

import anyio
import httpx

import ros_mobile_bridge as rmb

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import check_fates, subscription_counts
from _common import versions as common_versions
from _peer import IMAGE_TOPIC, STRING_TOPIC
from bench_foxglove import (
    IMAGE_MAX,
    STRING_MAX,
    Backend,
    ClientFactory,
    Count,
    Peer,
    Receiver,
    Sample,
    measure,
)

CLIENTS = ("default", "httpx")
NO_THROTTLE: Final = {"auto": [(0.0, 0.0, "full rate")]}
"""The adaptive throttle off (a flat curve) and no breaker: the blocked loop
of a drain is lag the throttle would answer by dropping frames (counted, by
design), which would measure the throttle, not the transport."""
CASES = (
    (STRING_TOPIC, "String 99 B", 5_000, STRING_MAX),
    (IMAGE_TOPIC, "Image 640x480", 30, IMAGE_MAX),
)


def client(kind: str) -> ClientFactory:
    """``rmb.connect`` + ``subscribe`` through the default transport or an
    httpx.AsyncClient (made per connection, closed after it)."""

    @asynccontextmanager
    async def factory(url: str, topic: str, count: int) -> AsyncIterator[Receiver]:
        async with httpx.AsyncClient() as http:
            options = rmb.ClientOptions(
                http_client=http if kind == "httpx" else None,
                preset_overrides=NO_THROTTLE,
                breaker=None,
            )
            async with (
                rmb.connect(url, protocol="foxglove-ws", options=options) as robot,
                robot.subscribe(topic, buffer=count) as sub,
            ):
                assert sub.state == "active"
                got = Count(count)

                async def run() -> None:
                    async for msg in sub:
                        got.bytes += len(msg.data.data)
                        got.n += 1
                        if got.n == count:
                            got.finish()

                yield Receiver(run, got, None, lambda: subscription_counts(sub))

    return factory


async def run_backend(
    peer: Peer, backend: Backend, seconds: float, reps: int
) -> tuple[dict[str, int], dict[str, dict[str, list[Sample]]], list[str]]:
    counts: dict[str, int] = {}
    for topic, _, probe, cap in CASES:
        calibration = await measure(peer, client("default"), topic, probe)
        counts[topic] = max(probe, min(cap, int(calibration.rate * seconds)))
    samples: dict[str, dict[str, list[Sample]]] = {
        topic: {name: [] for name in CLIENTS} for topic, *_ in CASES
    }
    problems: list[str] = []
    for rep in range(reps):
        for topic, label, _, _ in CASES:
            names = CLIENTS if rep % 2 == 0 else CLIENTS[::-1]  # alternate the order
            for name in names:
                sample = await measure(peer, client(name), topic, counts[topic])
                samples[topic][name].append(sample)
                where = f"{backend} {label} {name} rep {rep + 1}"
                if sample.frames != counts[topic]:
                    problems.append(f"{where}: {sample.frames} of {counts[topic]} received")
                problems += [
                    f"{where}: {p}" for p in check_fates(sample.extra, sent=sample.expected)
                ]
        print(f"  {backend}: repetition {rep + 1}/{reps} done", file=sys.stderr, flush=True)
    return counts, samples, problems


def report(
    backend: Backend, counts: dict[str, int], samples: dict[str, dict[str, list[Sample]]]
) -> dict[str, Any]:
    print(f"\n{backend}: medians")
    head = f"{'case':<16} {'client':<8} {'msgs':>7} {'msgs/s':>10} {'CPU us/msg':>11}"
    print(head)
    print("-" * len(head))
    summary: dict[str, Any] = {}
    for topic, label, _, _ in CASES:
        row: dict[str, dict[str, float]] = {}
        for name in CLIENTS:
            runs = samples[topic][name]
            row[name] = {
                "rate": statistics.median(s.rate for s in runs),
                "cpu_us": statistics.median(s.cpu_us for s in runs),
            }
            print(
                f"{label:<16} {name:<8} {counts[topic]:>7} {row[name]['rate']:>10,.0f}"
                f" {row[name]['cpu_us']:>11.1f}"
            )
        rate_ratio = row["httpx"]["rate"] / row["default"]["rate"]
        cpu_ratio = row["httpx"]["cpu_us"] / row["default"]["cpu_us"]
        print(f"{'':<16} {'httpx/default':<25} {rate_ratio:>4.2f}x rate, {cpu_ratio:>4.2f}x CPU")
        summary[topic] = {**row, "rate_ratio": rate_ratio, "cpu_ratio": cpu_ratio}
    return summary


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backend", choices=["asyncio", "trio", "both"], default="both")
    parser.add_argument("--seconds", type=float, default=1.0, help="target length of one drain")
    parser.add_argument("--reps", type=int, default=5, help="repetitions (medians are reported)")
    parser.add_argument("--json", type=Path, help="also write every sample and summary here")
    args = parser.parse_args()
    backends: list[Backend] = ["asyncio", "trio"] if args.backend == "both" else [args.backend]
    versions = common_versions(["ros-mobile-bridge", "websockets", "httpx", "httpcore", "anyio"])
    print(versions)
    print(
        f"{platform.machine()}, {len(os.sched_getaffinity(0))} CPUs;"
        " server: foxglove-sdk in a subprocess (bench/_peer.py)"
    )
    peer = Peer(backlog=max(STRING_MAX, IMAGE_MAX) + 1024)
    out: dict[str, Any] = {"versions": versions, "args": {**vars(args), "json": str(args.json)}}
    problems: list[str] = []
    try:
        for backend in backends:
            counts, samples, found = anyio.run(
                run_backend, peer, backend, args.seconds, args.reps, backend=backend
            )
            problems += found
            out[backend] = {
                "counts": counts,
                "summary": report(backend, counts, samples),
                "samples": {
                    topic: {name: [asdict(s) for s in runs] for name, runs in by.items()}
                    for topic, by in samples.items()
                },
            }
    finally:
        peer.close()
    out["problems"] = problems
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
        print(f"\nwrote {args.json}")
    if problems:
        print("\nFAILED: messages were lost:", file=sys.stderr)
        for problem in problems:
            print(f"  {problem}", file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()
