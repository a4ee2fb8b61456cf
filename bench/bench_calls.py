"""The per-frame path's length: the library's own Python calls per delivered
message, counted with ``cProfile`` on the event loop's thread, on each
transport against its real peer.

    .venv/bin/python bench/bench_calls.py [--transport foxglove|rosbridge|zenoh|all]

A count, not a time: it does not depend on the machine's load, so a change to
the hot path (socket -> adapter -> router -> queue -> ``async for``) shows as
a different number. Each case subscribes with ``adaptive=False`` and a buffer
that holds the burst, receives N ``std_msgs/String`` messages with
``async for``, and divides the calls of functions in ``ros_mobile_bridge``
(the consumer's decode included) by the messages received:

* ``foxglove``: the Foxglove SDK server of ``bench/_peer.py`` (a burst);
* ``rosbridge``: rosbridge_server_rs on a ROS 2 graph, a 2 kHz publisher
  (the peer environment of ``tests/peers``, set up on first use);
* ``zenoh``: the router and rmw_zenoh-style publisher of ``bench_zenoh.py``
  (a burst). Zenoh's callbacks run on zenoh's threads: what the session does
  there (one inbox item per sample) is not on the loop's thread and is not
  counted.

Add ``--detail`` for the calls per message of each function. To compare two
versions, run it with ``PYTHONPATH`` pointing at each one's ``src``.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import subprocess
import sys
from collections.abc import Callable
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import anyio

import ros_mobile_bridge as rmb

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE))

N = 20_000
N_ROSBRIDGE = 6_000  # at 2 kHz: 3 s


def report(name: str, prof: cProfile.Profile, got: int, detail: bool) -> float:
    stats = pstats.Stats(prof)
    ours = {
        key: calls
        for key, (_cc, calls, *_rest) in stats.stats.items()  # type: ignore[attr-defined]
        if "ros_mobile_bridge" in key[0]
    }
    per = sum(ours.values()) / got
    print(f"{name}: {got} messages, {per:.2f} library Python calls per message")
    if detail:
        for key, calls in sorted(ours.items(), key=lambda kv: -kv[1])[:20]:
            where = key[0].split("ros_mobile_bridge/")[-1]
            print(f"    {calls / got:6.2f}  {where}:{key[2]}")
    return per


async def _drain(sub: rmb.Subscription, count: int, prof: cProfile.Profile) -> int:
    got = 0
    prof.enable()
    try:
        while got < count:
            with anyio.move_on_after(5):
                await sub.__anext__()
                got += 1
                continue
            break  # nothing for 5 s: what came is what there is
    finally:
        prof.disable()
    return got


def foxglove(detail: bool) -> float:
    peer = subprocess.Popen(
        [sys.executable, str(HERE / "_peer.py"), str(N + 1024)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    assert peer.stdin is not None
    assert peer.stdout is not None
    port = int(peer.stdout.readline().split()[1])
    prof = cProfile.Profile()

    async def main() -> int:
        options = rmb.ClientOptions(zero_twist_on_exit=False)
        async with (
            rmb.connect(f"ws://127.0.0.1:{port}", options=options) as robot,
            robot.subscribe("/bench/string", adaptive=False, buffer=N + 1) as sub,
        ):
            await sub.wait_active()
            assert peer.stdin is not None
            peer.stdin.write(f"burst /bench/string {N}\n")
            peer.stdin.flush()
            return await _drain(sub, N, prof)

    try:
        got = anyio.run(main)
    finally:
        peer.stdin.write("quit\n")
        peer.stdin.flush()
        peer.wait(10)
    return report("foxglove", prof, got, detail)


def rosbridge(detail: bool) -> float:
    import bench_rosbridge as br

    from peers.ros_env import ensure_peer_env
    from peers.rosbridge import RosBridge, RosGraph

    env = ensure_peer_env()
    graph = RosGraph.start(env)
    prof = cProfile.Profile()
    try:
        bridge = RosBridge.start(env, graph.domain_id)
        try:
            publisher = br.StringPublisher(env, graph.domain_id, "/bench/calls", 2000.0)
            try:
                br.wait_topic(bridge, "/bench/calls", br.STRING_TYPE)

                async def main() -> int:
                    options = rmb.ClientOptions(reconnect=None, latency_probe_interval=0)
                    async with (
                        rmb.connect(bridge.url, protocol="rosbridge", options=options) as robot,
                        robot.subscribe("/bench/calls", buffer=100_000, adaptive=False) as sub,
                    ):
                        await sub.__anext__()
                        return await _drain(sub, N_ROSBRIDGE, prof)

                got = anyio.run(main)
            finally:
                publisher.stop()
        finally:
            bridge.stop()
    finally:
        graph.stop()
    return report("rosbridge", prof, got, detail)


def zenoh(detail: bool) -> float:
    import bench_zenoh as bz

    prof = cProfile.Profile()
    with ExitStack() as stack:
        locator, _which = bz.router(stack)
        publisher = bz.Publisher(locator, bz.DOMAIN)
        stack.callback(publisher.close)
        env = bz.Env(locator, bz.DOMAIN, publisher, "fit", False)

        async def main() -> int:
            async with bz.library(env, "string", N) as rx:
                await anyio.sleep(bz.SETTLE)
                async with anyio.create_task_group() as tg:
                    if rx.run is not None:
                        tg.start_soon(rx.run)
                    prof.enable()
                    sent = await anyio.to_thread.run_sync(env.publisher.burst, "string", N)
                    while rx.progress() < sent[0]:  # noqa: ASYNC110 - polled, as bench_zenoh does
                        await anyio.sleep(0.01)
                    prof.disable()
                    tg.cancel_scope.cancel()
            return int(rx.progress())

        got = anyio.run(main)
    return report("zenoh", prof, got, detail)


CASES: dict[str, Callable[[bool], float]] = {
    "foxglove": foxglove,
    "rosbridge": rosbridge,
    "zenoh": zenoh,
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--transport", choices=[*CASES, "all"], default="all")
    parser.add_argument("--detail", action="store_true", help="calls per message per function")
    args = parser.parse_args()
    names = list(CASES) if args.transport == "all" else [args.transport]
    out: dict[str, Any] = {}
    for name in names:
        out[name] = CASES[name](args.detail)


if __name__ == "__main__":
    main()
