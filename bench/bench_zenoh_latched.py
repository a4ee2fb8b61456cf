"""Latched topics over Zenoh: how long a late subscription waits for what a
transient-local publisher keeps, how much of it arrives, and how long after a
router restart the history comes again (stand-alone script; needs the
checkout: tests/peers/).

    .venv/bin/python bench/bench_zenoh_latched.py [--backend asyncio|trio]
        [--trials 10] [--depth 10]

Peers: an eclipse-zenoh router (tests/peers/zenoh_router.py, its own
process) and, in this process, raw eclipse-zenoh stand-ins of rmw_zenoh's
transient-local publishers of both forms (tests/peers/rmw_zenoh_latched.py).
For each form and trial a publisher of depth ``--depth`` publishes
``depth + 5`` messages; a client connects, waits until it sees the
publisher's token, subscribes, and the time from ``subscribe`` to the last
kept message is taken; every kept message (the newest ``depth``) must arrive,
in order, and nothing else. Then, with its own router, a subscription that
has the first message sees the router stopped, one message published while
it is down and the router started again: the time from the restart to that
message, and the duplicates skipped (``stats.dropped_replay``)."""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import anyio

import ros_mobile_bridge as rmb

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from peers.rmw_zenoh_latched import RmwPublisher  # type: ignore[import-not-found]
from peers.zenoh_router import ZenohRouter  # type: ignore[import-not-found]

STRING = "std_msgs/msg/String"
FORMS = ("advanced", "publication_cache")


async def until(predicate: Any, timeout: float, what: str) -> None:
    """Poll ``predicate`` (state other tasks and threads change) every ms."""
    with anyio.fail_after(timeout):
        while not predicate():  # noqa: ASYNC110 - a predicate, not one event
            await anyio.sleep(0.001)


async def late_join(locator: str, domain: int, form: str, depth: int) -> tuple[float, int]:
    """Seconds from ``subscribe`` to the last kept message, and how many came."""
    with RmwPublisher(locator, domain, "/kept", depth=depth, form=form) as pub:
        sent = [f"m{i}" for i in range(depth + 5)]
        for text in sent:
            pub.publish({"data": text})
        opts = rmb.ClientOptions(domain_id=domain)
        async with rmb.connect(locator, options=opts) as client:
            await until(lambda: client.topics, 10, "the publisher's token")
            start = time.perf_counter()
            got: list[str] = []
            async with client.subscribe("/kept", schema=STRING) as sub:
                with anyio.fail_after(10):
                    async for message in sub:
                        got.append(message.data.data)
                        if len(got) == depth:
                            break
                took = time.perf_counter() - start
            if got != sent[-depth:]:
                raise AssertionError(f"{form}: got {got}, expected {sent[-depth:]}")
            return took, len(got)


async def restart(domain: int, form: str) -> tuple[float, int]:
    """Seconds from the router's restart to the message kept meanwhile, and
    the duplicates skipped."""
    opts = rmb.ClientOptions(
        domain_id=domain,
        connect_timeout=2.0,
        keepalive_interval=0.2,
        keepalive_timeout=0.6,
        reconnect=rmb.ReconnectPolicy(initial_delay=0.1, max_delay=0.3),
    )
    router = ZenohRouter().start()
    try:
        with RmwPublisher(router.locator, domain, "/kept", depth=2, form=form) as pub:
            pub.publish({"data": "m1"})
            async with rmb.connect(router.locator, options=opts) as client:
                await until(lambda: client.topics, 10, "the publisher's token")
                got: list[str] = []
                async with (
                    client.subscribe("/kept", schema=STRING) as sub,
                    anyio.create_task_group() as tg,
                ):

                    async def collect() -> None:
                        async for message in sub:
                            got.append(message.data.data)

                    tg.start_soon(collect)
                    await until(lambda: got == ["m1"], 10, "m1")
                    router.stop()
                    await until(lambda: client.status == "reconnecting", 10, "reconnecting")
                    pub.publish({"data": "m2"})
                    router = ZenohRouter(port=router.port).start()
                    start = time.perf_counter()
                    await until(lambda: "m2" in got, 30, "m2")
                    took = time.perf_counter() - start
                    await until(lambda: sub.stats.dropped_replay >= 1, 10, "m1 skipped")
                    if got != ["m1", "m2"]:
                        raise AssertionError(f"{form}: got {got}")
                    tg.cancel_scope.cancel()
                return took, sub.stats.dropped_replay
    finally:
        router.stop()


async def main(args: argparse.Namespace) -> None:
    print(f"rmb {rmb.__version__}, {args.backend}, depth {args.depth}, {args.trials} trials")
    with ZenohRouter() as router:
        for form in FORMS:
            runs = [
                await late_join(router.locator, 100 + i, form, args.depth)
                for i in range(args.trials)
            ]
            times = sorted(t * 1000 for t, _ in runs)
            print(
                f"late join, {form:17}: {runs[0][1]} of {args.depth} kept messages each time;"
                f" subscribe -> last kept: median {statistics.median(times):.1f} ms,"
                f" max {times[-1]:.1f} ms"
            )
    for form in FORMS:
        runs = [await restart(150 + i, form) for i in range(max(args.trials // 2, 1))]
        times = sorted(t * 1000 for t, _ in runs)
        print(
            f"router restart, {form:17}: router up -> the message kept meanwhile:"
            f" median {statistics.median(times):.0f} ms, max {times[-1]:.0f} ms;"
            f" duplicates skipped {sorted({d for _, d in runs})}, none delivered"
        )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--backend", choices=("asyncio", "trio"), default="asyncio")
    parser.add_argument("--trials", type=int, default=10)
    parser.add_argument("--depth", type=int, default=10)
    arguments = parser.parse_args()
    anyio.run(main, arguments, backend=arguments.backend)
