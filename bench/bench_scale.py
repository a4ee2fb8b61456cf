"""Many connections in one process: connect time, idle cost, and a throttled
subscription each (stand-alone script).

    .venv/bin/python bench/bench_scale.py [--backend asyncio|trio|uvloop|both|all]
        [--sizes 10,100,1000] [--seconds 5] [--rate 20] [--max-hz 5] [--json PATH]
        [--strict] [--no-bare] [--profile] [--save-bandwidth]

The server is the official Foxglove SDK server in its own process
(``bench/_peer.py scale RATE``) on 127.0.0.1, with one ``std_msgs/String``
channel, ``/scale/tick``, logged RATE times a second whether or not anyone
listens. For each size N, in this process on one event loop:

1. **connect**: N tasks each open ``rmb.connect(url)`` at once; the time until
   all N are connected.
2. **idle**: after 1 s, this process's CPU time (``time.process_time()``, all
   threads) over ``--seconds`` while the N clients sit connected with no
   subscription: the cost of each client's own periodic work.
3. **subscribed**: every client subscribes to ``/scale/tick`` with
   ``max_hz=MAX_HZ`` (default adaptive throttle) and consumes it with ``async
   for`` touching ``msg.data.data``. Once the server has seen all N
   subscriptions, after 2 s, over ``--seconds``: messages delivered per
   second against the N x min(RATE, MAX_HZ) the caps allow, and CPU.
4. **memory**: this process's resident set (``/proc/self/statm``) with the N
   clients subscribed, minus what it was before they connected (after one
   warm-up client had connected and subscribed), over N.

Every subscription's fate counts are summed at the end of the window
(received, delivered, each drop reason, still queued); a run fails when
frames vanished or were dropped for any reason but the throttle or the
breaker (which may trip under overload; its drops show in the table). The
throttle's bucket of each subscription at the end is tallied too: a bucket
other than the cap's means the adaptive throttle tightened on the event
loop's lag.

5. **bare baseline** (unless ``--no-bare``): after the library's sizes, in
   the same process, on asyncio (on uvloop for the ``uvloop`` run), N bare
   ``websockets.asyncio.client``
   connections to the same server, each subscribing to ``/scale/tick`` with
   the Foxglove ws-protocol's JSON ``subscribe`` op and counting the binary
   frames it reads (every frame: no throttle, no decoding). Its CPU over a
   window of the same length is the floor of holding N such connections in
   Python; the library's subscribed CPU over it is printed as a ratio.

``--profile`` samples the library's subscribed window at the largest size
with a SIGPROF sampler (CPU time) and prints each function's share.

``--save-bandwidth`` subscribes with ``save_bandwidth=True``: each client
unsubscribes after every message it takes and subscribes again when the
next is due, so the server sends about MAX_HZ frames a second per client
instead of RATE (the bare baseline still reads every frame).

Loops: ``asyncio``, ``trio``, ``uvloop`` (asyncio on uvloop); ``both`` is
asyncio and trio, ``all`` the three. With ``both`` or ``all`` each loop runs
in its own process (memory one run freed stays in the process and would hide
the next one's growth).

Targets (issue 10), checked at the largest size: all connected within 5 s;
idle <= 1% of a core in total; subscribed >= 95% of the allowed rate
delivered at <= 50% of a core, <= 0.1 MB per connection.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import json
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import FrameType
from typing import Any, Final, Literal

import anyio
from websockets.asyncio.client import ClientConnection
from websockets.asyncio.client import connect as ws_connect
from websockets.typing import Subprotocol

import ros_mobile_bridge as rmb
from ros_mobile_bridge.wire.foxglove import SUBPROTOCOLS

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import DROP_REASONS, check_fates, run_on, subscription_counts, versions
from _peer import SCALE_TOPIC

Backend = Literal["asyncio", "trio", "uvloop"]
PEER: Final = Path(__file__).resolve().parent / "_peer.py"
PAGE: Final = os.sysconf("SC_PAGE_SIZE")
CONNECT_LIMIT_S: Final = 5.0
IDLE_LIMIT: Final = 0.01
SUB_CPU_LIMIT: Final = 0.50
DELIVERY_TARGET: Final = 0.95
MB_PER_CONNECTION_LIMIT: Final = 0.1


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * PAGE


class Peer:
    """The scale server in a subprocess."""

    def __init__(self, rate: float) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER), "scale", str(rate)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            bufsize=1,
        )
        assert self.proc.stdout is not None
        words = self.proc.stdout.readline().split()
        if words[:1] != ["port"]:
            raise RuntimeError(f"the scale peer did not start: {words!r}")
        self.url = f"ws://127.0.0.1:{words[1]}"

    def subscribers(self) -> int:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write("count\n")
        self.proc.stdin.flush()
        return int(self.proc.stdout.readline().split()[1])

    def close(self) -> None:
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write("quit\n")
            self.proc.stdin.close()
        except BrokenPipeError:
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


async def warm_up(url: str, max_hz: float) -> None:
    """One client connects, subscribes and takes a message: imports, codec
    caches and the decoder of the type exist before the baseline RSS."""
    async with rmb.connect(url) as client, client.subscribe(SCALE_TOPIC, max_hz=max_hz) as sub:
        with anyio.fail_after(10):
            async for _msg in sub:
                break


class Sampler:
    """A statistical profiler: SIGPROF on this process's CPU time, each
    sample charged to the interrupted Python function (own) and to every
    function on its stack (inclusive)."""

    def __init__(self) -> None:
        self.own: collections.Counter[str] = collections.Counter()
        self.total: collections.Counter[str] = collections.Counter()

    @staticmethod
    def where(frame: FrameType) -> str:
        code = frame.f_code
        path = code.co_filename
        for marker in (
            "site-packages/",
            "src/",
            f"python{sys.version_info[0]}.{sys.version_info[1]}/",
        ):
            if marker in path:
                path = path.split(marker, 1)[1]
                break
        return f"{path}:{code.co_name}"

    def sample(self, signum: int, frame: FrameType | None) -> None:
        if frame is None:
            return
        self.own[self.where(frame)] += 1
        seen: set[str] = set()
        f: FrameType | None = frame
        while f is not None:
            where = self.where(f)
            if where not in seen:
                seen.add(where)
                self.total[where] += 1
            f = f.f_back

    def start(self) -> None:
        signal.signal(signal.SIGPROF, self.sample)
        signal.setitimer(signal.ITIMER_PROF, 0.001, 0.001)

    def stop(self) -> None:
        signal.setitimer(signal.ITIMER_PROF, 0, 0)
        signal.signal(signal.SIGPROF, signal.SIG_DFL)

    def report(self, title: str) -> None:
        samples = sum(self.own.values()) or 1
        print(f"\nprofile, {title}: {samples} CPU samples (1 ms of CPU each)")
        print("  own time (the function itself):")
        for where, n in self.own.most_common(20):
            print(f"    {n / samples:6.1%}  {where}")
        print("  inclusive (the function and what it calls):")
        for where, n in self.total.most_common(30):
            print(f"    {n / samples:6.1%}  {where}")


async def run_size(
    peer: Peer,
    n: int,
    seconds: float,
    rate: float,
    max_hz: float,
    sampler: Sampler | None = None,
    save_bandwidth: bool = False,
) -> dict[str, Any]:
    rss_before = rss_bytes()
    connected = 0
    all_connected = anyio.Event()
    go = anyio.Event()
    delivered = [0] * n
    subs: list[rmb.Subscription] = []
    failures: list[str] = []

    async def client_task(i: int) -> None:
        nonlocal connected
        try:
            async with rmb.connect(peer.url) as client:
                connected += 1
                if connected == n:
                    all_connected.set()
                await go.wait()
                async with client.subscribe(
                    SCALE_TOPIC, max_hz=max_hz, save_bandwidth=save_bandwidth
                ) as sub:
                    subs.append(sub)
                    async for msg in sub:
                        _ = msg.data.data  # read the field, as a consumer does
                        delivered[i] += 1
        except rmb.RosBridgeError as exc:
            failures.append(f"client {i}: {exc!r}")
            all_connected.set()

    result: dict[str, Any] = {"n": n}
    async with anyio.create_task_group() as tg:
        start = time.perf_counter()
        for i in range(n):
            tg.start_soon(client_task, i)
        with anyio.fail_after(120):
            await all_connected.wait()
        result["connect_s"] = time.perf_counter() - start
        if failures:
            tg.cancel_scope.cancel()
            result["failures"] = failures
            return result

        await anyio.sleep(1.0)
        cpu0, t0 = time.process_time(), time.perf_counter()
        await anyio.sleep(seconds)
        result["idle_core"] = (time.process_time() - cpu0) / (time.perf_counter() - t0)
        result["idle_rss_mb_per_conn"] = (rss_bytes() - rss_before) / n / 1e6

        go.set()
        with anyio.fail_after(120):
            if save_bandwidth:  # paused clients leave the server's count
                while min(delivered) == 0:  # noqa: ASYNC110
                    await anyio.sleep(0.2)
            # the server is another process: its count can only be polled
            while not save_bandwidth and await anyio.to_thread.run_sync(peer.subscribers) < n:  # noqa: ASYNC110
                await anyio.sleep(0.2)
        await anyio.sleep(2.0)
        count0, cpu0, t0 = sum(delivered), time.process_time(), time.perf_counter()
        received0 = sum(s.stats.received for s in subs)
        if sampler is not None:
            sampler.start()
        try:
            await anyio.sleep(seconds)
        finally:
            if sampler is not None:
                sampler.stop()
        elapsed = time.perf_counter() - t0
        result["sub_core"] = (time.process_time() - cpu0) / elapsed
        result["delivered_per_s"] = (sum(delivered) - count0) / elapsed
        result["received_per_s"] = (sum(s.stats.received for s in subs) - received0) / elapsed
        result["allowed_per_s"] = n * min(rate, max_hz)
        result["sub_rss_mb_per_conn"] = (rss_bytes() - rss_before) / n / 1e6
        totals: collections.Counter[str] = collections.Counter()
        problems: list[str] = []
        may_drop: tuple[str, ...] = ("dropped_throttle", "dropped_breaker")
        if save_bandwidth:  # a replay is skipped (none expected: each tick differs)
            may_drop += ("dropped_replay",)
        for sub in subs:
            counts = subscription_counts(sub)
            totals.update(counts)
            # the breaker may trip under overload: counted, and it shows in
            # the delivered rate
            problems += check_fates(counts, may_drop=may_drop)
        result["fates"] = dict(totals)
        result["problems"] = problems[:5] + (
            [f"... {len(problems) - 5} more"] if len(problems) > 5 else []
        )
        result["buckets"] = dict(collections.Counter(s.stats.bucket or "-" for s in subs))
        tg.cancel_scope.cancel()
    return result


def verdicts(r: dict[str, Any]) -> list[tuple[str, bool]]:
    return [
        (
            f"all connected in {r['connect_s']:.2f} s (<= {CONNECT_LIMIT_S:g} s)",
            r["connect_s"] <= CONNECT_LIMIT_S,
        ),
        (
            f"idle {r['idle_core']:.1%} of a core (<= {IDLE_LIMIT:.0%})",
            r["idle_core"] <= IDLE_LIMIT,
        ),
        (
            f"delivered {r['delivered_per_s'] / r['allowed_per_s']:.1%} of the allowed"
            f" {r['allowed_per_s']:,.0f} msg/s (>= {DELIVERY_TARGET:.0%})",
            r["delivered_per_s"] >= DELIVERY_TARGET * r["allowed_per_s"],
        ),
        (
            f"subscribed {r['sub_core']:.1%} of a core (<= {SUB_CPU_LIMIT:.0%})",
            r["sub_core"] <= SUB_CPU_LIMIT,
        ),
        (
            f"{r['sub_rss_mb_per_conn']:.3f} MB per connection (<= {MB_PER_CONNECTION_LIMIT} MB)",
            r["sub_rss_mb_per_conn"] <= MB_PER_CONNECTION_LIMIT,
        ),
    ]


async def bare_client(
    url: str, counts: list[int], i: int, ready: asyncio.Event, failures: list[str]
) -> None:
    """One bare connection: subscribe to the scale topic's channel with the
    Foxglove JSON op, then count the binary frames read. A failure is
    recorded (and counts as ready: the run reports it)."""
    try:
        async with ws_connect(
            url,
            subprotocols=[Subprotocol(s) for s in SUBPROTOCOLS],
            max_size=None,
            compression=None,
            ping_interval=None,
            open_timeout=60,
        ) as ws:
            await bare_subscribe(ws)
            ready.set()
            async for message in ws:
                if isinstance(message, bytes):
                    counts[i] += 1
    except Exception as exc:
        failures.append(f"bare client {i}: {exc!r}")
        ready.set()


async def bare_subscribe(ws: ClientConnection) -> None:
    async for message in ws:
        if not isinstance(message, str):
            continue
        msg = json.loads(message)
        if msg.get("op") != "advertise":
            continue
        for channel in msg["channels"]:
            if channel["topic"] == SCALE_TOPIC:
                op = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]}
                await ws.send(json.dumps(op))
                return
    raise RuntimeError(f"the server closed before advertising {SCALE_TOPIC}")


async def run_bare(url: str, n: int, seconds: float) -> dict[str, Any]:
    """N bare ``websockets`` connections subscribed to the scale topic, on
    asyncio: binary frames read per second and this process's CPU over a
    window of ``seconds``, 2 s after all N subscribed."""
    counts = [0] * n
    failures: list[str] = []
    readies = [asyncio.Event() for _ in range(n)]
    tasks = [
        asyncio.create_task(bare_client(url, counts, i, readies[i], failures)) for i in range(n)
    ]
    try:
        await asyncio.wait_for(asyncio.gather(*(r.wait() for r in readies)), 120)
        await asyncio.sleep(2.0)
        count0, cpu0, t0 = sum(counts), time.process_time(), time.perf_counter()
        await asyncio.sleep(seconds)
        elapsed = time.perf_counter() - t0
        return {
            "n": n,
            "core": (time.process_time() - cpu0) / elapsed,
            "frames_per_s": (sum(counts) - count0) / elapsed,
            "failures": failures[:3] + ([f"... {len(failures)} in all"] if failures else []),
        }
    finally:
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)


async def run_backend(args: argparse.Namespace) -> list[dict[str, Any]]:
    peer = Peer(args.rate)
    try:
        await warm_up(peer.url, args.max_hz)
        results = []
        for n in args.sizes:
            sampler = Sampler() if args.profile and n == max(args.sizes) else None
            r = await run_size(
                peer, n, args.seconds, args.rate, args.max_hz, sampler, args.save_bandwidth
            )
            results.append(r)
            if sampler is not None:
                r["profile"] = sampler
            await anyio.sleep(1.0)  # let the server see the previous clients go
        return results
    finally:
        peer.close()


def bare_baseline(args: argparse.Namespace, n: int, backend: Backend) -> dict[str, Any]:
    """:func:`run_bare` on a fresh scale server, in this process, on asyncio
    (on uvloop for the ``uvloop`` run: the same loop as the library's)."""
    peer = Peer(args.rate)
    try:
        return run_on(
            "uvloop" if backend == "uvloop" else "asyncio", run_bare, peer.url, n, args.seconds
        )
    finally:
        peer.close()


def run_each_backend(args: argparse.Namespace) -> int:
    """``--backend both`` / ``all``: this script once per loop, in a subprocess."""
    codes = []
    out: dict[str, Any] = {}
    loops = ("asyncio", "trio", "uvloop") if args.backend == "all" else ("asyncio", "trio")
    for backend in loops:
        argv = [
            sys.executable,
            __file__,
            "--backend",
            backend,
            "--sizes",
            ",".join(map(str, args.sizes)),
        ]
        argv += [
            "--seconds",
            str(args.seconds),
            "--rate",
            str(args.rate),
            "--max-hz",
            str(args.max_hz),
        ]
        if args.strict:
            argv.append("--strict")
        if args.no_bare:
            argv.append("--no-bare")
        if args.profile:
            argv.append("--profile")
        if args.save_bandwidth:
            argv.append("--save-bandwidth")
        part = args.json.with_suffix(f".{backend}.json") if args.json else None
        if part is not None:
            argv += ["--json", str(part)]
        codes.append(subprocess.run(argv, check=False).returncode)
        if part is not None and part.exists():
            out.update(json.loads(part.read_text()))
            part.unlink()
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
        print(f"\nwrote {args.json}")
    return max(codes)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--backend", choices=["asyncio", "trio", "uvloop", "both", "all"], default="both"
    )
    parser.add_argument("--sizes", default="10,100,1000", help="connection counts, comma-separated")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of each measured window")
    parser.add_argument("--rate", type=float, default=20.0, help="the topic's rate (Hz)")
    parser.add_argument("--max-hz", type=float, default=5.0, help="each subscription's max_hz")
    parser.add_argument("--json", type=Path)
    parser.add_argument("--strict", action="store_true", help="a missed target fails the run")
    parser.add_argument("--no-bare", action="store_true", help="skip the bare websockets baseline")
    parser.add_argument(
        "--save-bandwidth", action="store_true", help="subscribe with save_bandwidth=True"
    )
    parser.add_argument(
        "--profile", action="store_true", help="profile the subscribed window at the largest size"
    )
    args = parser.parse_args()
    args.sizes = [int(x) for x in args.sizes.split(",")]
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    need = 2 * max(args.sizes) + 256
    if soft < need:
        resource.setrlimit(resource.RLIMIT_NOFILE, (min(need, hard), hard))
    if args.backend in ("both", "all"):
        # each backend in a fresh process: memory freed by one run stays in the
        # process (RSS does not shrink), which would hide the next one's growth
        return run_each_backend(args)
    backends: list[Backend] = [args.backend]
    print(versions(["ros-mobile-bridge", "anyio", "trio", "foxglove-sdk"]))
    print(
        f"{os.cpu_count()} CPUs; one Foxglove SDK server in a subprocess, {SCALE_TOPIC} at"
        f" {args.rate:g} Hz; every client max_hz={args.max_hz:g}; windows of {args.seconds:g} s"
    )
    out: dict[str, Any] = {}
    failed: list[str] = []
    missed: list[str] = []
    for backend in backends:
        results = run_on(backend, run_backend, args)
        profiles = [r.pop("profile") for r in results if "profile" in r]
        out[backend] = results
        print(f"\n{backend}:")
        print(
            f"  {'conns':>6} {'connect s':>9} {'idle core':>9} {'idle MB/conn':>12}"
            f" {'sub core':>8} {'delivered/s':>11} {'allowed/s':>9} {'received/s':>10}"
            f" {'MB/conn':>7}  buckets"
        )
        for r in results:
            if "failures" in r:
                print(f"  {r['n']:>6} connect failed: {r['failures'][:3]}")
                failed.append(f"{backend} n={r['n']}: connect failed")
                continue
            buckets = ", ".join(f"{k} x{v}" for k, v in sorted(r["buckets"].items()))
            print(
                f"  {r['n']:>6} {r['connect_s']:>9.2f} {r['idle_core']:>9.1%}"
                f" {r['idle_rss_mb_per_conn']:>12.3f} {r['sub_core']:>8.1%}"
                f" {r['delivered_per_s']:>11,.0f} {r['allowed_per_s']:>9,.0f}"
                f" {r['received_per_s']:>10,.0f} {r['sub_rss_mb_per_conn']:>7.3f}  {buckets}"
            )
        for r in results:
            if "failures" in r:
                continue
            fates = r["fates"]
            print(
                f"  fates at n={r['n']}: received {fates['received']:,}, delivered"
                f" {fates['delivered']:,}, "
                + ", ".join(f"{d} {fates[d]:,}" for d in DROP_REASONS)
                + f", queued {fates['queued']:,}"
                + (f"; PROBLEMS: {r['problems']}" if r["problems"] else "; ok")
            )
            if r["problems"]:
                failed.append(f"{backend} n={r['n']}: {r['problems']}")
        last = next((r for r in reversed(results) if "failures" not in r), None)
        if last is not None:
            print(f"  targets at n={last['n']}:")
            for text, ok in verdicts(last):
                print(f"    {'PASS' if ok else 'MISS'}  {text}")
                if not ok:
                    missed.append(f"{backend}: {text}")
            if not args.no_bare:
                bare = bare_baseline(args, last["n"], backend)
                last["bare"] = bare
                loop = "uvloop" if backend == "uvloop" else "asyncio"
                print(
                    f"  bare websockets ({loop}), {bare['n']:,} connections reading every frame:"
                    f" {bare['core']:.1%} of a core, {bare['frames_per_s']:,.0f} frames/s;"
                    f" library/bare CPU {last['sub_core'] / bare['core']:.2f}"
                    f" (the library read {last['received_per_s']:,.0f} frames/s)"
                    + (f"; FAILED: {bare['failures']}" if bare["failures"] else "")
                )
        for profile in profiles:
            profile.report(f"{backend}, the subscribed window at n={max(args.sizes)}")
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
        print(f"\nwrote {args.json}")
    if missed:
        print("\nmissed targets:\n  " + "\n  ".join(missed))
    if failed:
        print("FAILED: " + "; ".join(failed), file=sys.stderr)
        return 1
    return 1 if (missed and args.strict) else 0


if __name__ == "__main__":
    sys.exit(main())
