"""End-to-end receive benchmark against the official Foxglove SDK server (stand-alone script).

    .venv/bin/python bench/bench_foxglove.py [--backend asyncio|trio|uvloop|both|all] [--seconds 1]
        [--reps 5] [--json PATH] [--malloc default|steady] [--profile]

The server (``foxglove-sdk``) runs in a subprocess, ``bench/_peer.py``, so its
CPU never shares the client's GIL. Client CPU time is ``time.process_time()``
of this process (user + system, every thread) over the measured window; minor
page faults come from ``getrusage``.

Two ways to feed the client:

* a *drain*: the client connects and subscribes, then its event loop is
  blocked on purpose while the server publishes a fixed number of messages as
  fast as it can into its per-client backlog (raised so that nothing is
  dropped). The loop is released and the client receives them all; the window
  runs from the release to the last message. The client is saturated
  throughout and the publisher's CPU does not compete with it.
* *paced*: the server publishes a fixed number of messages at a fixed rate
  while the client receives (a fast topic as a robot would have one).

Cases: String (``std_msgs/msg/String``, 90 characters, a 99-byte CDR payload)
and Image (``sensor_msgs/msg/Image`` 640x480 rgb8, 921,652 bytes) drains;
a String drain with ``max_hz=10``; String paced at 2 kHz, with and without
``max_hz=10``.

Clients:

* ``library``: ``rmb.connect`` + ``robot.subscribe(topic, buffer=N)``,
  ``async for msg in sub`` touching ``msg.data.data`` (decoded);
* ``transport``: the library's own WebSocket (``transport.connect_websocket``)
  in a raw loop counting binary frames (no Foxglove parsing, no decoding);
* ``websockets``: ``websockets.asyncio.client`` in the same raw loop (asyncio
  and uvloop; websockets has no trio client, so on trio ``transport`` is the
  baseline).

Loops: ``asyncio``, ``trio`` and ``uvloop`` (asyncio on uvloop: the
``websockets`` client then runs on the same uvloop); ``both`` is asyncio and
trio, ``all`` the three, and a run with asyncio and uvloop also prints the
library on uvloop against the library on asyncio.

A calibration drain sizes each drain case so that one library drain lasts
about ``--seconds`` (a paced run lasts twice that); every client gets the same
count. Repetitions interleave the clients (their order rotates); the table
shows medians. See ``bench/README.md`` for what each number means.
"""

from __future__ import annotations

import argparse
import collections
import ctypes
import ctypes.util
import json
import os
import platform
import resource
import signal
import statistics
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Awaitable, Callable, Coroutine
from contextlib import AbstractAsyncContextManager, asynccontextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from types import FrameType
from typing import Any, Final, Literal, NamedTuple

import anyio
from websockets.asyncio.client import connect as ws_connect
from websockets.typing import Subprotocol

import ros_mobile_bridge as rmb
from ros_mobile_bridge.transport import connect_websocket

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import DROP_REASONS, check_fates, run_on, subscription_counts
from _common import versions as common_versions
from _peer import IMAGE_TOPIC, STRING_TOPIC, payloads

Backend = Literal["asyncio", "trio", "uvloop"]
SUBPROTOCOL: Final = "foxglove.sdk.v1.1"
PEER: Final = Path(__file__).resolve().parent / "_peer.py"
TICK: Final = 0.005
"""How often a drain's watcher samples progress (seconds)."""
PACED_TICK: Final = 0.02
"""The same for paced runs, after sleeping through the expected duration."""
IDLE: Final = 1.0
"""A run ends early when nothing arrived for this long (messages were lost)."""
STRING_MAX: Final = 400_000
IMAGE_MAX: Final = 400
"""At most this many images (about 370 MB) wait in the server's backlog."""
PACE_HZ: Final = 2000.0
PAYLOAD_SIZE: Final = {topic: len(p) for topic, p in payloads().items()}


# -- the publisher process ---------------------------------------------------------


class Peer:
    """``bench/_peer.py`` in a subprocess, driven over its stdin and stdout.

    Its methods block the calling thread, and so the event loop: on purpose
    for :meth:`burst` (the client reads nothing until the burst is queued),
    briefly for the others."""

    def __init__(self, backlog: int) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER), str(backlog)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self._in, self._out = self.proc.stdin, self.proc.stdout
        port = self._answer("port")
        self.url = f"ws://127.0.0.1:{port[0]}"

    def _answer(self, expected: str) -> list[str]:
        words = self._out.readline().split()
        if not words or words[0] != expected:
            raise RuntimeError(f"publisher: {' '.join(words) or 'exited'}")
        return words[1:]

    def _send(self, line: str) -> None:
        self._in.write(line + "\n")
        self._in.flush()

    def burst(self, topic: str, count: int) -> None:
        """Publish ``count`` messages on ``topic`` as fast as possible, once the
        new subscriber is there; returns when all are queued."""
        self._send(f"burst {topic} {count}")
        self._answer("done")

    def pace(self, topic: str, count: int, rate: float) -> None:
        """Start publishing ``count`` messages at ``rate`` per second once the
        new subscriber is there; :meth:`wait_done` after receiving them."""
        self._send(f"pace {topic} {count} {rate}")
        self._answer("started")

    def wait_done(self) -> None:
        self._answer("done")

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self._send("quit")
                self._in.close()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


# -- the clients -------------------------------------------------------------------


class Stamp(NamedTuple):
    wall: float
    cpu: float
    faults: int


def stamp() -> Stamp:
    """Now: wall clock, this process's CPU time, its minor page faults."""
    return Stamp(
        time.perf_counter(),
        time.process_time(),
        resource.getrusage(resource.RUSAGE_SELF).ru_minflt,
    )


class Count:
    """What a receive loop received. The loop stamps the end of the window
    itself when the ``target``-th frame arrives."""

    __slots__ = ("bytes", "end", "n", "target")

    def __init__(self, target: int) -> None:
        self.target = target
        self.n = 0
        self.bytes = 0
        self.end: Stamp | None = None

    def finish(self) -> None:
        self.end = stamp()


@dataclass
class Receiver:
    """A subscribed client: ``run`` receives forever into ``got``. ``progress``
    counts frames received when the loop does not see every one (throttled)."""

    run: Callable[[], Coroutine[Any, Any, None]]
    got: Count
    progress: Callable[[], int] | None = None
    extra: Callable[[], dict[str, int]] = dict


ClientFactory = Callable[[str, str, int], AbstractAsyncContextManager[Receiver]]


def library(
    max_hz: float | None = None, read_coalesce: float | None = None, batches: bool = False
) -> ClientFactory:
    """The full client: receive, route, throttle, decode, deliver. Default
    options but ``read_coalesce`` when given; ``batches``: the consumer
    iterates ``sub.batches()`` instead of ``sub``."""
    options = rmb.ClientOptions()
    if read_coalesce is not None:
        options = replace(options, read_coalesce=read_coalesce)

    @asynccontextmanager
    async def factory(url: str, topic: str, count: int) -> AsyncIterator[Receiver]:
        async with (
            rmb.connect(url, protocol="foxglove-ws", options=options) as robot,
            robot.subscribe(topic, buffer=count, max_hz=max_hz) as sub,
        ):
            assert sub.state == "active"
            got = Count(count)

            async def run() -> None:
                async for msg in sub:
                    got.bytes += len(msg.data.data)
                    got.n += 1
                    if got.n == count:
                        got.finish()

            async def run_batches() -> None:
                async for batch in sub.batches():
                    for msg in batch:
                        got.bytes += len(msg.data.data)
                        got.n += 1
                        if got.n == count:
                            got.finish()

            def extra() -> dict[str, int]:
                return subscription_counts(sub)

            progress = (lambda: sub.stats.received) if max_hz else None
            yield Receiver(run_batches if batches else run, got, progress, extra)

    return factory


async def _subscribe_raw(
    receive: Callable[[], Awaitable[str | bytes]],
    send: Callable[[str], Awaitable[None]],
    topic: str,
) -> None:
    """Find ``topic`` in the server's advertisements and subscribe to it (id 1)."""
    while True:
        message = await receive()
        if isinstance(message, str):
            op = json.loads(message)
            if op.get("op") == "advertise":
                for ch in op["channels"]:
                    if ch["topic"] == topic:
                        sub = {"id": 1, "channelId": ch["id"]}
                        await send(json.dumps({"op": "subscribe", "subscriptions": [sub]}))
                        return


@asynccontextmanager
async def transport(url: str, topic: str, count: int) -> AsyncIterator[Receiver]:
    """The library's WebSocket alone: a raw loop counting binary frames."""
    ws = await connect_websocket(url, subprotocols=(SUBPROTOCOL,), max_size=None)
    try:
        await _subscribe_raw(ws.receive, ws.send, topic)
        got = Count(count)

        async def run() -> None:
            receive = ws.receive
            while True:
                message = await receive()
                if not isinstance(message, str):
                    got.bytes += len(message)
                    got.n += 1
                    if got.n == count:
                        got.finish()

        yield Receiver(run, got)
    finally:
        await ws.aclose()


@asynccontextmanager
async def websockets_asyncio(url: str, topic: str, count: int) -> AsyncIterator[Receiver]:
    """``websockets.asyncio.client``: a raw loop counting binary frames."""
    async with ws_connect(
        url,
        subprotocols=[Subprotocol(SUBPROTOCOL)],
        compression=None,
        max_size=None,
        ping_interval=None,
        proxy=None,
    ) as ws:
        await _subscribe_raw(ws.recv, ws.send, topic)
        got = Count(count)

        async def run() -> None:
            async for message in ws:
                if not isinstance(message, str):
                    got.bytes += len(message)
                    got.n += 1
                    if got.n == count:
                        got.finish()

        yield Receiver(run, got)


# -- one measurement ---------------------------------------------------------------


@dataclass
class Sample:
    """One run: ``frames`` received of ``expected`` over ``seconds`` of wall
    time, ``cpu`` seconds of this process's CPU time, ``faults`` minor page
    faults."""

    frames: int
    expected: int
    seconds: float
    cpu: float
    faults: int
    extra: dict[str, int] = field(default_factory=dict)

    @property
    def rate(self) -> float:
        return self.frames / self.seconds if self.seconds > 0 else 0.0

    @property
    def cpu_us(self) -> float:
        return self.cpu / self.frames * 1e6 if self.frames else 0.0


async def measure(
    peer: Peer, factory: ClientFactory, topic: str, count: int, pace: float | None = None
) -> Sample:
    """Subscribe, have ``count`` messages published (a drain, or paced at
    ``pace`` per second), receive them, measure."""
    async with factory(peer.url, topic, count) as rx:
        if pace is None:
            peer.burst(topic, count)  # blocks the event loop until all are queued
            first_wait, tick = TICK, TICK
        else:
            peer.pace(topic, count, pace)
            first_wait, tick = count / pace, PACED_TICK  # no polling while they arrive
        start = last = stamp()
        seen = 0
        got, progress = rx.got, rx.progress
        async with anyio.create_task_group() as tg:
            tg.start_soon(rx.run)
            await anyio.sleep(first_wait)
            while True:
                n = progress() if progress is not None else got.n
                if n != seen:
                    last, seen = stamp(), n
                    if n >= count:
                        break
                elif time.perf_counter() - last.wall > IDLE:
                    break  # lost messages: the window ends at the last progress seen
                await anyio.sleep(tick)
            tg.cancel_scope.cancel()
        if pace is not None:
            peer.wait_done()
        end = got.end or last  # the loop's own stamp at the count-th frame is exact
        return Sample(
            seen,
            count,
            end.wall - start.wall,
            end.cpu - start.cpu,
            end.faults - start.faults,
            rx.extra(),
        )


# -- the run -----------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    key: str
    label: str
    topic: str
    clients: dict[str, ClientFactory]
    pace: float | None = None


def cases(backend: Backend) -> list[Case]:
    raw: dict[str, ClientFactory] = {"transport": transport}
    if backend != "trio":  # (on uvloop too: websockets' asyncio client on uvloop's loop)
        raw["websockets"] = websockets_asyncio
    capped = {"library max_hz=10": library(max_hz=10)}
    return [
        Case(
            "string",
            "String 99 B",
            STRING_TOPIC,
            {"library": library(), "library batches": library(batches=True), **raw},
        ),
        Case("image", "Image 640x480 rgb8", IMAGE_TOPIC, {"library": library(), **raw}),
        Case("string_hz10", "String, max_hz=10", STRING_TOPIC, capped),
        Case(
            "paced",
            f"String paced {PACE_HZ / 1000:g} kHz",
            STRING_TOPIC,
            {
                "library": library(),
                "library read_coalesce=0": library(read_coalesce=0.0),
                **capped,
                **raw,
            },
            pace=PACE_HZ,
        ),
    ]


@dataclass
class Result:
    counts: dict[str, int]
    cases: list[Case]
    samples: dict[str, dict[str, list[Sample]]]
    problems: list[str] = field(default_factory=list)
    """Frames that vanished or were dropped where nothing may drop them."""


async def run_backend(peer: Peer, backend: Backend, seconds: float, reps: int) -> Result:
    """Calibrate, then ``reps`` interleaved repetitions of every case and client."""
    counts: dict[str, int] = {}
    for topic, probe, cap in ((STRING_TOPIC, 5_000, STRING_MAX), (IMAGE_TOPIC, 30, IMAGE_MAX)):
        calibration = await measure(peer, library(), topic, probe)
        counts[topic] = max(probe, min(cap, int(calibration.rate * seconds)))
    paced_count = max(200, int(PACE_HZ * seconds * 2))
    all_cases = cases(backend)
    samples: dict[str, dict[str, list[Sample]]] = {
        c.key: {name: [] for name in c.clients} for c in all_cases
    }
    for rep in range(reps):
        for case in all_cases:
            names = list(case.clients)
            names = names[rep % len(names) :] + names[: rep % len(names)]  # rotate the order
            count = paced_count if case.pace else counts[case.topic]
            for name in names:
                sample = await measure(peer, case.clients[name], case.topic, count, case.pace)
                samples[case.key][name].append(sample)
        print(f"  {backend}: repetition {rep + 1}/{reps} done", file=sys.stderr, flush=True)
    counts["paced"] = paced_count
    return Result(counts, all_cases, samples)


# -- profiling (--profile) -----------------------------------------------------------


def _where(frame: FrameType) -> str:
    code = frame.f_code
    path = code.co_filename
    for marker in ("site-packages/", "src/", f"python{sys.version_info[0]}.{sys.version_info[1]}/"):
        if marker in path:
            path = path.split(marker, 1)[1]
            break
    if path == "<string>" and frame.f_back is not None:  # generated code: say whose
        return f"<generated {code.co_name}> in {_where(frame.f_back)}"
    return f"{path}:{code.co_name}"


async def profile_library(
    peer: Peer, topic: str, count: int, backend: Backend, drains: int = 5
) -> None:
    """Library drains under a statistical profiler (SIGPROF on CPU time, user
    and system; the interrupted Python frame); prints the shares of samples."""
    own: collections.Counter[str] = collections.Counter()
    total: collections.Counter[str] = collections.Counter()

    def sample(signum: int, frame: FrameType | None) -> None:
        if frame is None:
            return
        own[_where(frame)] += 1
        seen: set[str] = set()
        f: FrameType | None = frame
        while f is not None:
            where = _where(f)
            if where not in seen:
                seen.add(where)
                total[where] += 1
            f = f.f_back

    previous = signal.signal(signal.SIGPROF, sample)
    signal.setitimer(signal.ITIMER_PROF, 0.0005, 0.0005)
    try:
        for _ in range(drains):  # connecting is profiled too: a few ms of CPU per drain
            await measure(peer, library(), topic, count)
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0, 0)
        signal.signal(signal.SIGPROF, previous)
    samples = sum(own.values())
    print(f"\nprofile, {backend}: {drains} library drains of {topic}, {samples} CPU samples")
    print("  own time (the function itself):")
    for where, n in own.most_common(16):
        print(f"    {n / samples:6.1%}  {where}")
    print("  inclusive (the function and what it calls):")
    skip = ("asyncio/", "anyio/", "trio/", "/")  # event loop and bench frames
    shown = [(w, n) for w, n in total.most_common(60) if not w.startswith(skip) and "<" not in w]
    for where, n in shown[:14]:
        print(f"    {n / samples:6.1%}  {where}")


# -- reporting ---------------------------------------------------------------------


def summarize(samples: list[Sample], payload: int) -> dict[str, float]:
    rate = statistics.median([s.rate for s in samples])
    cpu = [s.cpu_us for s in samples]
    cpu_us = statistics.median(cpu)
    return {
        "frames_per_s": rate,
        "mb_per_s": rate * payload / 1e6,
        "cpu_us_per_frame": cpu_us,
        "cpu_us_per_frame_min": min(cpu),
        "cpu_util": statistics.median([s.cpu / s.seconds for s in samples if s.seconds > 0]),
        "faults_per_frame": statistics.median([s.faults / max(s.frames, 1) for s in samples]),
        "cpu_spread": (max(cpu) - min(cpu)) / cpu_us if cpu_us else 0.0,
        "lost": float(sum(s.expected - s.frames for s in samples)),
        "delivered": statistics.median([s.extra.get("delivered", s.frames) for s in samples]),
    }


def fmt_rate(value: float) -> str:
    return f"{value / 1e3:.1f} k" if value >= 1e4 else f"{value:.0f}  "


def report(backend: Backend, result: Result) -> dict[str, dict[str, dict[str, float]]]:
    """Print the backend's table and ratios; return the summaries."""
    counts = result.counts
    table: dict[str, dict[str, dict[str, float]]] = {}
    print(
        f"\n{backend}: drains of {counts[STRING_TOPIC]:,} strings / {counts[IMAGE_TOPIC]:,}"
        f" images, {counts['paced']:,} paced strings; medians of"
        f" {len(result.samples['string']['library'])}"
    )
    print(
        f"  {'case':<22} {'client':<18} {'frames/s':>9} {'MB/s':>7} {'CPU us/frame':>12}"
        f" {'(min)':>8} {'spread':>6} {'CPU util':>8} {'faults/frame':>12} {'lost':>4}"
    )
    for case in result.cases:
        payload = PAYLOAD_SIZE[case.topic]
        table[case.key] = {}
        for name, samples in result.samples[case.key].items():
            s = table[case.key][name] = summarize(samples, payload)
            print(
                f"  {case.label:<22} {name:<18} {fmt_rate(s['frames_per_s']):>9}"
                f" {s['mb_per_s']:7.1f} {s['cpu_us_per_frame']:12.2f}"
                f" {s['cpu_us_per_frame_min']:8.2f} {s['cpu_spread']:6.0%} {s['cpu_util']:8.0%}"
                f" {s['faults_per_frame']:12.1f} {s['lost']:4.0f}"
            )

    print("  fate of every frame the library received (sums over the repetitions):")
    print(
        f"  {'case':<22} {'client':<18} {'sent':>8} {'delivered':>9} {'throttle':>8}"
        f" {'conflated':>9} {'overflow':>8} {'breaker':>7} {'replay':>6} {'queued':>6}  verdict"
    )
    for case in result.cases:
        sent = counts["paced"] if case.pace else counts[case.topic]
        for name, samples in result.samples[case.key].items():
            if not name.startswith("library"):
                continue
            may_drop = ("dropped_throttle",) if "max_hz" in name else ()
            problems = [
                f"{case.label} / {name}, repetition {i + 1}: {problem}"
                for i, sample in enumerate(samples)
                for problem in check_fates(sample.extra, sent=sent, may_drop=may_drop)
            ]
            result.problems.extend(problems)
            total = {k: sum(s.extra.get(k, 0) for s in samples) for k in samples[0].extra}
            print(
                f"  {case.label:<22} {name:<18} {sent * len(samples):8d} {total['delivered']:9d}"
                + "".join(
                    f" {total[r]:{w}d}" for r, w in zip(DROP_REASONS, (8, 9, 8, 7, 6), strict=True)
                )
                + f" {total['queued']:6d}  {'FAIL' if problems else 'ok'}"
            )

    def ratio(key: str, a: str, b: str) -> str:
        x, y = table[key][a], table[key][b]
        return (
            f"{x['frames_per_s'] / y['frames_per_s']:.2f}x frames/s,"
            f" {x['cpu_us_per_frame'] / y['cpu_us_per_frame']:.2f}x CPU/frame"
        )

    base = "websockets" if backend != "trio" else "transport"
    print(f"  ratios (medians), library / {base}:")
    for key in ("string", "image"):
        line = f"    {key:<7} {ratio(key, 'library', base)}"
        if base != "transport":
            line += f"   (library / transport: {ratio(key, 'library', 'transport')})"
        print(line)
    print(f"    string, library batches / {base}: {ratio('string', 'library batches', base)}")
    paced = table["paced"]
    print(
        f"    paced   {paced['library']['cpu_us_per_frame'] / paced[base]['cpu_us_per_frame']:.2f}x"
        " CPU/frame"
    )
    print("  max_hz=10, CPU us per received frame (library / library max_hz=10 / transport):")
    for label, key, capped_key in (
        ("drain", "string", "string_hz10"),
        ("paced", "paced", "paced"),
    ):
        lib, capped = table[key]["library"], table[capped_key]["library max_hz=10"]
        expected = counts[STRING_TOPIC] if label == "drain" else counts["paced"]
        print(
            f"    {label}  {lib['cpu_us_per_frame']:.2f} / {capped['cpu_us_per_frame']:.2f}"
            f" / {table[key]['transport']['cpu_us_per_frame']:.2f}"
            f"   ({capped['delivered']:.0f} of {expected:,} delivered with the cap)"
        )
    return table


def versions() -> str:
    return common_versions(
        ("ros-mobile-bridge", "websockets", "anyio", "trio", "rosbags", "foxglove-sdk")
    )


def steady_malloc() -> None:
    """glibc: keep freed memory instead of returning it to the kernel, so a new
    large frame does not page-fault in fresh pages (``M_MMAP_THRESHOLD`` 32 MiB,
    ``M_TRIM_THRESHOLD`` 1 GiB)."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    if not (libc.mallopt(-3, 32 << 20) and libc.mallopt(-1, 1 << 30)):
        raise SystemExit("mallopt failed (glibc only)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--backend", choices=["asyncio", "trio", "uvloop", "both", "all"], default="both"
    )
    parser.add_argument(
        "--seconds", type=float, default=1.0, help="target length of one library run"
    )
    parser.add_argument("--reps", type=int, default=5, help="repetitions (medians are reported)")
    parser.add_argument("--json", type=Path, help="also write every sample and summary here")
    parser.add_argument(
        "--malloc",
        choices=["default", "steady"],
        default="default",
        help="steady: stop glibc returning freed memory to the kernel (see README)",
    )
    parser.add_argument(
        "--profile", action="store_true", help="also profile library String and Image drains"
    )
    args = parser.parse_args()
    backends: list[Backend] = {
        "both": ["asyncio", "trio"],
        "all": ["asyncio", "trio", "uvloop"],
    }.get(args.backend, [args.backend])
    if args.malloc == "steady":
        steady_malloc()

    print(versions())
    print(
        f"{platform.machine()}, {len(os.sched_getaffinity(0))} CPUs, malloc {args.malloc};"
        " server: foxglove-sdk in a subprocess; 1 MB = 1e6 bytes of CDR payload"
    )
    peer = Peer(backlog=STRING_MAX + 1024)
    out: dict[str, Any] = {"versions": versions(), "args": {**vars(args), "json": str(args.json)}}
    try:
        for backend in backends:
            result = run_on(backend, run_backend, peer, backend, args.seconds, args.reps)
            out[backend] = {
                "counts": result.counts,
                "summary": report(backend, result),
                "problems": result.problems,
                "samples": {
                    key: {name: [asdict(s) for s in lst] for name, lst in by_client.items()}
                    for key, by_client in result.samples.items()
                },
            }
            if args.profile:
                for topic in (STRING_TOPIC, IMAGE_TOPIC):
                    count = result.counts[topic]
                    run_on(backend, profile_library, peer, topic, count, backend)
    finally:
        peer.close()
    if "asyncio" in out and "uvloop" in out:
        print("\nthe library on uvloop / on asyncio (medians; CPU per frame: lower is better):")
        for key in ("string", "image", "paced"):
            a, u = (
                out["asyncio"]["summary"][key]["library"],
                out["uvloop"]["summary"][key]["library"],
            )
            print(
                f"  {key:<7} {u['frames_per_s'] / a['frames_per_s']:.2f}x frames/s,"
                f" {u['cpu_us_per_frame'] / a['cpu_us_per_frame']:.2f}x CPU/frame"
            )
    problems = [p for backend in backends for p in out[backend]["problems"]]
    out["problems"] = problems
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
        print(f"\nwrote {args.json}")
    if problems:
        print("\nFAILED: the library lost frames it must deliver:", file=sys.stderr)
        for problem in problems:
            print(f"  {problem}", file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()
