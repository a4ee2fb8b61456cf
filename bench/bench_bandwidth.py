"""Bytes on the wire against bytes delivered, with and without ``save_bandwidth``
(stand-alone script).

    .venv/bin/python bench/bench_bandwidth.py [--backend asyncio|trio|both]
        [--protocol foxglove|zenoh|both] [--seconds 4] [--json PATH]
        [--only image|string]

On Foxglove the protocol has no rate option: the server sends every message
whatever ``max_hz`` says, so the cap saves the client's CPU and not the link.
``save_bandwidth=True`` unsubscribes after each message taken and subscribes
again when the next one is due. This bench measures, for each case with the
mode off and on:

* ``conn MB``: what the client read from its socket (``Client.stats()``, over
  the run: from subscribing to the end of the stream);
* ``sub MB``: the payload bytes routed to the subscription
  (``sub.stats.bytes_received``);
* ``deliv MB``: the payload bytes of the messages delivered to the consumer;
* ``wire/deliv``: ``conn MB`` over ``deliv MB`` (1.0 would be perfect);
* the mode's cost: messages delivered, the mean interval between deliveries
  and the publisher's messages between two deliveries (each message carries
  its sequence number), against the default mode.

Cases (the server, ``bench/_peer.py``, in its own process: ``stamped``
publishes on a fixed schedule, each message stamped with its sequence number
so that no two are the same, as a camera's stamps make them):

* ``image 30Hz max_hz 5`` and ``max_hz 1``: ``sensor_msgs/msg/Image`` 640x480
  rgb8 (921,652 bytes) at 30 Hz;
* ``string 2kHz max_hz 10``: ``std_msgs/msg/String`` (99 bytes) at 2 kHz.

The same cases run over Zenoh (``--protocol zenoh``; the ``[zenoh]``
extra): an eclipse-zenoh router and ``bench/_zenoh_publisher.py``'s
publisher in their own processes (``bench_zenoh.py``'s peers), the samples
paced at the case's rate, each numbered by its rmw_zenoh attachment. There
``conn MB`` is the zenoh samples' payload bytes (``Client.stats()``: zenoh's
own framing is not visible to the client), and nothing is replayed.

Subscriptions use ``adaptive=False`` (a loaded machine's lag must not move
the interval) and ``decode=False`` (decoding is not what is measured). Every
frame's fate is checked (``_common.check_fates``): a run fails when frames
vanish. Target: images in the mode at most 1.5x the delivered bytes.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Final, Literal

import anyio

import ros_mobile_bridge as rmb

sys.path.insert(0, str(Path(__file__).resolve().parent))
import itertools
from collections.abc import Callable
from contextlib import ExitStack

from _common import check_fates, subscription_counts, versions
from _peer import IMAGE_TOPIC, STRING_TOPIC, stamp_of
from bench_foxglove import Peer
from bench_zenoh import TOPIC as ZENOH_TOPIC
from bench_zenoh import Publisher, router

Backend = Literal["asyncio", "trio"]
TAIL: Final = 1.2
"""Seconds the client keeps reading after the last message was published: the
trailing delivery of the slowest cap (1 Hz) and what is in flight."""
TARGET: Final = 1.5
"""Images in the mode: at most this many bytes read per byte delivered."""


class StampedPeer(Peer):
    """``bench/_peer.py`` with its ``stamped`` command."""

    def stamped(self, topic: str, count: int, rate: float) -> None:
        """Start publishing ``count`` stamped messages at ``rate`` per second
        once the new subscriber is there; :meth:`wait_done` after."""
        self._send(f"stamped {topic} {count} {rate}")
        self._answer("started")


@dataclass(frozen=True)
class Case:
    label: str
    topic: str
    rate: float
    max_hz: float
    kind: str


CASES: Final = (
    Case("image 30Hz max_hz 5", IMAGE_TOPIC, 30.0, 5.0, "image"),
    Case("image 30Hz max_hz 1", IMAGE_TOPIC, 30.0, 1.0, "image"),
    Case("string 2kHz max_hz 10", STRING_TOPIC, 2000.0, 10.0, "string"),
)


@dataclass
class Run:
    case: str
    protocol: str
    backend: str
    save_bandwidth: bool
    sent: int
    delivered: int
    conn_bytes: int
    sub_bytes: int
    delivered_bytes: int
    wire_per_delivered: float
    mean_interval_ms: float
    published_between: float
    fates: dict[str, int]
    problems: list[str]


@dataclass(frozen=True)
class Bridge:
    """Where a case runs: how to connect, the topic of a kind, how to have
    ``count`` messages published at ``rate`` (blocking until they are) and
    a delivered message's sequence number."""

    name: str
    url: str
    protocol: Literal["foxglove-ws", "zenoh"]
    options: rmb.ClientOptions
    topic: Callable[[Case], str]
    publish: Callable[[Case, int], None]
    seq: Callable[[Case, rmb.Message], int]


def foxglove(peer: StampedPeer) -> Bridge:
    def publish(case: Case, count: int) -> None:
        peer.stamped(case.topic, count, case.rate)
        peer.wait_done()

    return Bridge(
        "foxglove",
        peer.url,
        "foxglove-ws",
        rmb.ClientOptions(connect_timeout=10.0, advertise_settle=0.0, reconnect=None),
        lambda case: case.topic,
        publish,
        lambda case, msg: stamp_of(case.topic, msg.data),
    )


def zenoh(locator: str, domain: int, publisher: Publisher) -> Bridge:
    def publish(case: Case, count: int) -> None:
        publisher.burst("image" if case.kind == "image" else "string", count, case.rate)

    def seq(case: Case, msg: rmb.Message) -> int:
        assert msg.sequence is not None
        return msg.sequence

    return Bridge(
        "zenoh",
        locator,
        "zenoh",
        rmb.ClientOptions(connect_timeout=10.0, reconnect=None, domain_id=domain),
        lambda case: ZENOH_TOPIC["image" if case.kind == "image" else "string"][0],
        publish,
        seq,
    )


async def run_case(bridge: Bridge, case: Case, mode: bool, seconds: float, backend: str) -> Run:
    count = max(int(case.rate * seconds), 1)
    seqs: list[int] = []
    times: list[int] = []
    delivered_bytes = 0
    async with rmb.connect(bridge.url, protocol=bridge.protocol, options=bridge.options) as robot:
        before = robot.stats().bytes_received
        async with robot.subscribe(
            bridge.topic(case),
            max_hz=case.max_hz,
            adaptive=False,
            save_bandwidth=mode,
            decode=False,
            buffer=4096,
        ) as sub:

            async def consume() -> None:
                nonlocal delivered_bytes
                async for msg in sub:
                    seqs.append(bridge.seq(case, msg))
                    times.append(msg.receive_time_ns)
                    delivered_bytes += msg.byte_size

            async with anyio.create_task_group() as tg:
                tg.start_soon(consume)
                await anyio.to_thread.run_sync(bridge.publish, case, count)
                await anyio.sleep(TAIL)
                counts = subscription_counts(sub)
                stats = sub.stats
                conn = robot.stats().bytes_received - before
                tg.cancel_scope.cancel()
    may_drop = ("dropped_throttle", "dropped_replay")
    problems = check_fates(counts, may_drop=may_drop)
    if len(seqs) != counts["delivered"]:
        problems.append(f"{counts['delivered']} delivered, {len(seqs)} consumed")
    if seqs != sorted(set(seqs)):
        problems.append("deliveries out of order or repeated")
    intervals = [(b - a) / 1e6 for a, b in itertools.pairwise(times)]
    between = [b - a for a, b in itertools.pairwise(seqs)]
    return Run(
        case=case.label,
        protocol=bridge.name,
        backend=backend,
        save_bandwidth=mode,
        sent=count,
        delivered=len(seqs),
        conn_bytes=conn,
        sub_bytes=stats.bytes_received,
        delivered_bytes=delivered_bytes,
        wire_per_delivered=conn / delivered_bytes if delivered_bytes else float("inf"),
        mean_interval_ms=statistics.fmean(intervals) if intervals else 0.0,
        published_between=statistics.fmean(between) if between else 0.0,
        fates=counts,
        problems=problems,
    )


def report(runs: list[Run]) -> None:
    print(
        f"  {'protocol':<9} {'case':<22} {'mode':<5} {'sent':>6} {'deliv':>6} {'interval ms':>11}"
        f" {'pub between':>11} {'deliv MB':>9} {'sub MB':>8} {'conn MB':>8} {'wire/deliv':>10}"
        f" {'replay':>6}  verdict"
    )
    for r in runs:
        print(
            f"  {r.protocol:<9} {r.case:<22} {'on' if r.save_bandwidth else 'off':<5} {r.sent:6d}"
            f" {r.delivered:6d} {r.mean_interval_ms:11.1f} {r.published_between:11.1f}"
            f" {r.delivered_bytes / 1e6:9.3f} {r.sub_bytes / 1e6:8.3f} {r.conn_bytes / 1e6:8.3f}"
            f" {r.wire_per_delivered:9.2f}x {r.fates.get('dropped_replay', 0):6d}"
            f"  {'FAIL' if r.problems else 'ok'}"
        )


async def run_backend(
    backend: Backend, protocols: list[str], seconds: float, only: str | None
) -> tuple[list[Run], list[str]]:
    runs: list[Run] = []
    problems: list[str] = []
    with ExitStack() as stack:
        bridges: list[Bridge] = []
        if "foxglove" in protocols:
            peer = StampedPeer(1024)
            stack.callback(peer.close)
            bridges.append(foxglove(peer))
        if "zenoh" in protocols:
            locator, _ = router(stack)
            domain = 77
            publisher = Publisher(locator, domain)
            stack.callback(publisher.close)
            bridges.append(zenoh(locator, domain, publisher))
        for bridge in bridges:
            await run_cases(bridge, backend, seconds, only, runs, problems)
    return runs, problems


async def run_cases(
    bridge: Bridge,
    backend: Backend,
    seconds: float,
    only: str | None,
    runs: list[Run],
    problems: list[str],
) -> None:
    """Every case over ``bridge``, without and with the mode."""
    for case in CASES:
        if only is not None and case.kind != only:
            continue
        for mode in (False, True):
            run = await run_case(bridge, case, mode, seconds, backend)
            runs.append(run)
            where = f"{backend} / {bridge.name} / {case.label}"
            problems += [f"{where} / mode {'on' if mode else 'off'}: {p}" for p in run.problems]
            if mode and case.kind == "image" and run.wire_per_delivered > TARGET:
                problems.append(
                    f"{where}: {run.wire_per_delivered:.2f}x the delivered"
                    f" bytes read in the mode (target {TARGET}x)"
                )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backend", choices=("asyncio", "trio", "both"), default="both")
    parser.add_argument("--seconds", type=float, default=4.0, help="publishing per run")
    parser.add_argument("--only", choices=("image", "string"), default=None)
    parser.add_argument("--protocol", choices=("foxglove", "zenoh", "both"), default="both")
    parser.add_argument("--json", type=Path, default=None, help="write the results here")
    args = parser.parse_args()
    backends: list[Backend] = ["asyncio", "trio"] if args.backend == "both" else [args.backend]
    print(versions(["ros-mobile-bridge", "foxglove-sdk", "eclipse-zenoh", "anyio", "trio"]))
    every: list[Run] = []
    problems: list[str] = []
    for backend in backends:
        print(f"{backend}:")
        protocols = ["foxglove", "zenoh"] if args.protocol == "both" else [args.protocol]
        runs, found = anyio.run(
            run_backend, backend, protocols, args.seconds, args.only, backend=backend
        )
        report(runs)
        every += runs
        problems += found
    if args.json is not None:
        args.json.write_text(
            json.dumps({"runs": [asdict(r) for r in every], "problems": problems}, indent=2)
        )
    if problems:
        print("FAILED: " + "; ".join(problems))
        sys.exit(1)


if __name__ == "__main__":
    main()
