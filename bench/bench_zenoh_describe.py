"""First-message latency of a type learnt from the robot (stand-alone script).

    .venv/bin/python bench/bench_zenoh_describe.py [--backend asyncio|trio] [--reps 9]

Everything runs on 127.0.0.1 and nothing is downloaded. An eclipse-zenoh
router (``tests/peers/zenoh_router.py``) and two zenoh-ros2-sdk talkers
(``tests/peers/zenoh_sdk_node.py``, fed the ROS 2 Jazzy peer environment's
official interface files) publish at 200 Hz: ``/known``, a
``std_msgs/msg/String`` the library has built in, and ``/described``, a
``test_msgs/msg/Nested`` it does not know; that talker's node serves
``get_type_description`` (REP-2011).

One run: a fresh client connects, waits until the topic is in the graph,
then the clock starts, it subscribes, and the clock stops when the first
*decoded* message comes out of ``async for``. Three cases, alternated in a
rotating order in every repetition:

* ``known``: ``/known`` (the bundled definition; its decoder is already
  built in the process after the first run);
* ``fetched``: ``/described`` with the process cache of descriptions
  emptied first, so the client asks the node, checks the hash, registers
  the definitions and decodes (the built CDR codec stays in the process's
  codec cache after the first run, as for ``known``);
* ``cached``: ``/described`` again, the description already in the process
  cache (what a second connection sees).

The table gives the median and the spread (min-max) over ``--reps`` in ms,
and each case's median as a ratio of ``known``'s. The talkers publish every
5 ms, so up to 5 ms of every figure is the wait for the next sample. The run
FAILS (exit 1) when a first message is not decoded, or when the node did not
answer exactly once per ``fetched`` run and never for ``cached`` ones.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import anyio

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE.parent / "src"))

import ros_mobile_bridge as rmb  # noqa: E402
from ros_mobile_bridge.codec import DESCRIPTION_CACHE  # noqa: E402

NESTED_VALUES = {"basic_types_value": {"int32_value": 7, "float64_value": 0.5}}
CASES = ("known", "fetched", "cached")
TOPIC = {"known": "/known", "fetched": "/described", "cached": "/described"}


async def first_message(locator: str, domain: int, case: str) -> float:
    """Seconds from subscribe to the first decoded message of ``case``."""
    if case == "fetched":
        DESCRIPTION_CACHE.clear()
    topic = TOPIC[case]
    options = rmb.ClientOptions(domain_id=domain)
    async with rmb.connect(locator, options=options) as client:
        with anyio.fail_after(20):
            async for topics in client.watch_topics():
                if any(t.name == topic for t in topics):
                    break
        start = time.perf_counter()
        async with client.subscribe(topic) as sub:
            async for message in sub:
                elapsed = time.perf_counter() - start
                if message.decode_error is not None:
                    raise SystemExit(f"FAILED: {case}: {message.decode_error}")
                return elapsed
    raise AssertionError("unreachable")


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--backend", choices=["asyncio", "trio"], default="asyncio")
    parser.add_argument("--reps", type=int, default=9)
    parser.add_argument("--json", type=Path, help="write the figures here")
    args = parser.parse_args(argv)

    from peers.ros_env import ensure_peer_env
    from peers.zenoh_router import ZenohRouter
    from peers.zenoh_sdk_node import SdkNode

    share = ensure_peer_env().prefix / "share"
    domain = 77
    times: dict[str, list[float]] = {case: [] for case in CASES}
    with ZenohRouter() as router:
        rate = ("--rate", "200")
        known = SdkNode(router.locator, domain, share, "talker", "--topic", "/known", *rate)
        described = SdkNode(
            router.locator,
            domain,
            share,
            "talker",
            "--topic",
            "/described",
            "--type",
            "test_msgs/msg/Nested",
            "--values",
            json.dumps(NESTED_VALUES),
            "--describe",
            *rate,
        )
        with known, described:
            for rep in range(args.reps + 1):  # the first is a discarded warm-up
                order = CASES[rep % 3 :] + CASES[: rep % 3]
                for case in order:
                    answered = len(described.described())
                    seconds = anyio.run(
                        first_message, router.locator, domain, case, backend=args.backend
                    )
                    asked = len(described.described()) - answered
                    # the order always runs a fetch before the first "cached"
                    want = 1 if case == "fetched" else 0
                    if asked != want:
                        print(f"FAILED: {case}: the node answered {asked} times, not {want}")
                        return 1
                    if rep:
                        times[case].append(seconds * 1000.0)
    base = statistics.median(times["known"])
    print(f"first decoded message after subscribe, {args.backend}, {args.reps} runs each")
    print(f"{'case':<8} {'median ms':>10} {'min-max ms':>16} {'x known':>8}")
    figures: dict[str, Any] = {}
    for case in CASES:
        median = statistics.median(times[case])
        low, high = min(times[case]), max(times[case])
        print(f"{case:<8} {median:>10.1f} {f'{low:.1f}-{high:.1f}':>16} {median / base:>8.2f}")
        figures[case] = {"median_ms": median, "min_ms": low, "max_ms": high}
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
