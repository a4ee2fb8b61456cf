"""Zenoh receive benchmark: this library against a bare eclipse-zenoh callback (stand-alone script).

    .venv/bin/python bench/bench_zenoh.py [--backend asyncio|trio|both] [--reps 5]
        [--strings 400000] [--images 1000] [--backlog fit|default] [--no-adaptive]
        [--json PATH] [--strict]

Everything runs on 127.0.0.1; nothing is downloaded.

**The router** is an eclipse-zenoh session in router mode in its own process,
listening on ``tcp/127.0.0.1:<free port>`` only (multicast and gossip
scouting off, shared memory off): ``tests/peers/zenoh_router.py``'s
``ZenohRouter`` when that module exists, else ``bench/_zenoh_publisher.py
router``.

**The publisher** (``bench/_zenoh_publisher.py publisher``) is another process,
so its CPU never shares this process's GIL: a zenoh *client* session (shared
memory off) with one publisher per topic on the exact rmw_zenoh data key
(``<domain>/bench/<name>/<dds type>/<RIHS01 hash>``), reliable, congestion
control BLOCK, and an rmw_zenoh publisher liveliness token. Payloads are CDR:
``std_msgs/msg/String`` with 90 characters (99 bytes) and
``sensor_msgs/msg/Image`` 640x480 ``rgb8`` (921,652 bytes). Every sample
carries the 33-byte rmw_zenoh attachment (sequence number, timestamp, gid).

**A burst.** A client subscribes; after a pause for the declaration to reach
the router (``SETTLE``), the publisher is told to put N samples. It waits
until a subscriber matches its key, then puts them as fast as its loop goes
(BLOCK: a full link makes ``put`` wait, nothing is dropped on the way). The
client receives concurrently. The window runs from the publisher's first
``put`` (its ``CLOCK_MONOTONIC``, the same clock as this process's) to the
moment the client has the N-th message (or, if some were dropped, the last
progress); the rates are the messages received (bare) or delivered (library)
over that window.
CPU time is ``time.process_time()`` of this process (user + system, all its
threads, zenoh's included) from the command to the N-th message. Only the
client runs in this process.

**The clients**, each with a fresh session per burst, in this process:

* ``bare``: ``zenoh.open`` (client mode, shared memory off) and
  ``declare_subscriber("<domain>/bench/<name>/*/*", callback)``, a callback
  that only counts samples and payload bytes (``len(sample.payload)``). The
  baseline: what eclipse-zenoh alone delivers to Python.
* ``library``: ``async with rmb.connect("tcp/127.0.0.1:PORT", options=...) as
  client, client.subscribe(topic, schema=..., buffer=N) as sub: async for msg
  in sub:`` touching ``msg.data.data`` (the decoded ``str``, or the
  image's numpy array), on asyncio or trio. The subscription keeps the
  default adaptive throttle: when the event loop lags it drops frames
  (counted as ``dropped_throttle``); ``--no-adaptive`` subscribes with
  ``adaptive=False``. Its warnings go to a logger that only counts them.

The library's zenoh inbox (samples waiting between zenoh's threads and the
reader task) is bounded by ``ClientOptions.zenoh_backlog`` (8192 samples)
and ``zenoh_backlog_bytes`` (64 MiB) by default. The publisher outruns the
library on purpose, so a whole burst may wait there. With ``--backlog fit``
(the default) both bounds are raised to hold one burst (N samples, N x
payload bytes): then the inbox cannot overflow, and the figures are the
library's throughput, not its drop rate. ``--backlog default`` keeps the
defaults, to show what overflows. Either way the table prints how many
samples and bytes ever waited in the inbox at once (sampled every 5 ms), so
the default's headroom can be read off.

**Every message's fate is counted.** For the library: the publisher's sent
count; ``sub.stats`` (delivered, each drop reason) and what is still queued
(``_common.subscription_counts``); ``client.rejections`` (``backlog_overflow``:
the inbox was full; ``attachment`` and ``malformed``: samples skipped). A
run FAILS (exit 1) when sent != delivered + counted drops + queued, i.e.
messages vanished, when frames vanished inside the subscription
(``_common.check_fates``), or when the bare counter did not receive every
message. Counted drops are reported, not failures.

The machine's load averages are printed before and after each backend: the
router, the publisher and this process share the CPUs, and other work on
them moves every rate.

One discarded warm-up burst per payload and client comes first. Repetitions
alternate the clients (the order rotates) for each payload; the
tables show medians over ``--reps``. Targets, per backend: the library at
least 0.5x the bare counter's msgs/s for the String, at least 0.8x its MB/s
for the Image; each is printed as PASS or MISS, and only ``--strict`` makes a
miss fail the run.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import select
import signal
import socket
import statistics
import subprocess
import sys
import time
from collections.abc import AsyncIterator, Callable, Coroutine, Iterator
from contextlib import AbstractAsyncContextManager, ExitStack, asynccontextmanager, contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, Final, Literal

import anyio
import anyio.to_thread
import zenoh

import ros_mobile_bridge as rmb

HERE: Final = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
from _common import DROP_REASONS, check_fates, client_internals, subscription_counts  # noqa: E402
from _common import versions as common_versions  # noqa: E402
from _zenoh_publisher import IMAGE_TOPIC, IMAGE_TYPE, STRING_TOPIC, STRING_TYPE  # noqa: E402
from _zenoh_publisher import config as zenoh_config  # noqa: E402

Backend = Literal["asyncio", "trio"]
Kind = Literal["string", "image"]
KINDS: Final[tuple[Kind, ...]] = ("string", "image")
CLIENTS: Final = ("bare", "library")
PEER: Final = HERE / "_zenoh_publisher.py"
SHARED_ROUTER: Final = HERE.parent / "tests" / "peers" / "zenoh_router.py"
DOMAIN: Final = 42
TOPIC: Final[dict[Kind, tuple[str, str]]] = {
    "string": (STRING_TOPIC, STRING_TYPE),
    "image": (IMAGE_TOPIC, IMAGE_TYPE),
}
LABEL: Final[dict[Kind, str]] = {"string": "String 99 B", "image": "Image 640x480 rgb8"}
TARGET: Final[dict[Kind, tuple[str, float]]] = {"string": ("msgs/s", 0.5), "image": ("MB/s", 0.8)}
"""Per payload: the rate compared and the least library / bare ratio that meets the target."""
DATA_REJECTIONS: Final = ("attachment", "malformed")
"""``client.rejections`` reasons that are data samples skipped before a subscription."""
SETTLE: Final = 0.2
"""Seconds after subscribing before the burst: the declaration reaches the router."""
TICK: Final = 0.005
"""How often the watcher samples progress and the inbox (seconds)."""
IDLE: Final = 2.0
"""A burst ends early when nothing progressed for this long after the last put."""
START_TIMEOUT: Final = 30.0
REPLY_TIMEOUT: Final = 120.0
WARMUP: Final[dict[Kind, int]] = {"string": 5_000, "image": 20}
DEFAULTS: Final = rmb.ClientOptions()


class CountingHandler(logging.Handler):
    """Counts the library's warnings instead of printing them: one is logged
    per skipped sample, and the fate table has the counts."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.count = 0

    def emit(self, record: logging.LogRecord) -> None:
        self.count += 1


LIBRARY_LOG: Final = CountingHandler()
LOGGER: Final = logging.getLogger("bench_zenoh.library")
LOGGER.addHandler(LIBRARY_LOG)
LOGGER.propagate = False


def monotonic() -> float:
    """``CLOCK_MONOTONIC`` seconds: the publisher process stamps with the same clock."""
    return time.clock_gettime(time.CLOCK_MONOTONIC)


# -- the peer processes ----------------------------------------------------------------


def read_line(proc: subprocess.Popen[str], timeout: float, what: str) -> list[str]:
    """The next line ``proc`` prints, split; ``RuntimeError`` when it exits or
    says nothing for ``timeout`` seconds."""
    assert proc.stdout is not None
    ready, _, _ = select.select([proc.stdout], [], [], timeout)
    if not ready:
        raise RuntimeError(f"{what}: no answer within {timeout:g} s")
    line = proc.stdout.readline()
    if not line:
        raise RuntimeError(f"{what}: exited with {proc.wait()}")
    return line.split()


def start_peer(*args: str) -> subprocess.Popen[str]:
    """``bench/_zenoh_publisher.py`` with ``args``; it exits when its stdin closes."""
    return subprocess.Popen(
        [sys.executable, str(PEER), *args],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )


def stop_peer(proc: subprocess.Popen[str]) -> None:
    """Close its stdin (it exits by itself) and wait; kill it if it does not."""
    if proc.poll() is None:
        try:
            if proc.stdin is not None:
                proc.stdin.close()
            proc.wait(timeout=10)
        except (OSError, subprocess.TimeoutExpired):
            proc.kill()
            proc.wait()
    if proc.stdout is not None:
        proc.stdout.close()


def free_port() -> int:
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port: int = sock.getsockname()[1]
        return port


@contextmanager
def own_router() -> Iterator[str]:
    """A router process on a free loopback port; yields its locator."""
    for attempt in range(3):
        locator = f"tcp/127.0.0.1:{free_port()}"
        proc = start_peer("router", locator)
        try:
            words = read_line(proc, START_TIMEOUT, "router")
            if words != ["ready"]:
                raise RuntimeError(f"router: {' '.join(words)}")
        except RuntimeError:
            stop_peer(proc)
            if attempt == 2:
                raise
            continue  # the port was taken in between: another one
        try:
            yield locator
        finally:
            stop_peer(proc)
        return


def router(stack: ExitStack) -> tuple[str, str]:
    """Start the router for the run (closed with ``stack``): ``(locator, what)``."""
    if SHARED_ROUTER.exists():
        sys.path.insert(0, str(SHARED_ROUTER.parents[1]))
        try:
            from peers.zenoh_router import ZenohRouter  # type: ignore[import-not-found]

            shared = stack.enter_context(ZenohRouter())
            return str(shared.locator), "tests/peers/zenoh_router.py"
        except (ImportError, TypeError, AttributeError) as exc:
            print(f"not using {SHARED_ROUTER.name} ({exc}); own router", file=sys.stderr)
    return stack.enter_context(own_router()), "bench/_zenoh_publisher.py router"


class Publisher:
    """The publisher process, driven over its stdin and stdout."""

    def __init__(self, locator: str, domain: int) -> None:
        self.proc = start_peer("publisher", locator, str(domain))
        try:
            words = read_line(self.proc, START_TIMEOUT, "publisher")
            if not words or words[0] != "ready":
                raise RuntimeError(f"publisher: {' '.join(words)}")
        except BaseException:
            stop_peer(self.proc)
            raise
        self.sizes: dict[Kind, int] = {"string": int(words[1]), "image": int(words[2])}

    def burst(self, kind: Kind, count: int, rate: float | None = None) -> tuple[int, float, float]:
        """Have ``count`` samples of ``kind`` put, as fast as it goes or at
        ``rate`` a second (blocks until they are): ``(sent, start, end)`` of
        the puts, ``CLOCK_MONOTONIC`` seconds."""
        assert self.proc.stdin is not None
        command = f"burst {kind} {count}" if rate is None else f"paced {kind} {count} {rate}"
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()
        timeout = REPLY_TIMEOUT + (0.0 if rate is None else count / rate)
        words = read_line(self.proc, timeout, "publisher")
        if len(words) != 4 or words[0] != "done":
            raise RuntimeError(f"publisher: {' '.join(words)}")
        return int(words[1]), float(words[2]), float(words[3])

    def close(self) -> None:
        stop_peer(self.proc)


@dataclass
class Env:
    locator: str
    domain: int
    publisher: Publisher
    backlog: str
    """``fit``: the library's zenoh inbox holds one burst; ``default``: the defaults."""
    adaptive: bool = True
    """The library subscription's ``adaptive`` throttle (``--no-adaptive`` turns it off)."""


# -- the clients ---------------------------------------------------------------------------


class Got:
    """What a client received; ``end`` is ``(monotonic, process_time)`` at the
    ``target``-th message, stamped where it arrives."""

    __slots__ = ("bytes", "end", "n", "target")

    def __init__(self, target: int) -> None:
        self.target = target
        self.n = 0
        self.bytes = 0
        self.end: tuple[float, float] | None = None


@dataclass
class Receiver:
    """A subscribed client. ``run`` (if any) receives in a task; ``progress``
    counts the messages whose fate is settled (delivered or dropped, counted);
    ``fates`` is the final count of every fate; ``watch`` samples queue
    depths on every tick."""

    got: Got
    progress: Callable[[], int]
    fates: Callable[[], dict[str, int]]
    run: Callable[[], Coroutine[Any, Any, None]] | None = None
    watch: Callable[[], None] | None = None


ClientFactory = Callable[[Env, Kind, int], AbstractAsyncContextManager[Receiver]]


def selector(domain: int, kind: Kind) -> str:
    """What the library subscribes to for the topic: any type, any hash."""
    return f"{domain}/{TOPIC[kind][0].lstrip('/')}/*/*"


@asynccontextmanager
async def bare(env: Env, kind: Kind, count: int) -> AsyncIterator[Receiver]:
    """eclipse-zenoh alone: a client session and a callback that counts."""
    session = await anyio.to_thread.run_sync(zenoh.open, zenoh_config("client", env.locator))
    try:
        got = Got(count)

        def on_sample(sample: zenoh.Sample) -> None:
            got.n += 1
            got.bytes += len(sample.payload)
            if got.n == count:
                got.end = (monotonic(), time.process_time())

        subscriber = session.declare_subscriber(selector(env.domain, kind), on_sample)
        try:
            yield Receiver(got, lambda: got.n, lambda: {"received": got.n, "bytes": got.bytes})
        finally:
            subscriber.undeclare()  # type: ignore[no-untyped-call]
    finally:
        with anyio.CancelScope(shield=True):
            await anyio.to_thread.run_sync(session.close)


def backlog(env: Env, kind: Kind, count: int) -> tuple[int, int]:
    """The library's zenoh inbox bounds, samples and bytes (see ``--backlog``)."""
    if env.backlog == "default":
        return DEFAULTS.zenoh_backlog, DEFAULTS.zenoh_backlog_bytes
    return (
        max(DEFAULTS.zenoh_backlog, count),
        max(DEFAULTS.zenoh_backlog_bytes, count * env.publisher.sizes[kind] + (1 << 20)),
    )


def _inbox_of(client: rmb.Client) -> Any:
    """The client's zenoh inbox (private; None if the layout changed)."""
    session = getattr(client_internals(client)[0], "_session", None)
    return getattr(session, "inbox", None)


@asynccontextmanager
async def library(env: Env, kind: Kind, count: int) -> AsyncIterator[Receiver]:
    """The full client: zenoh callback, inbox, reader, subscription queue, decoding."""
    topic, schema = TOPIC[kind]
    samples, size = backlog(env, kind, count)
    options = rmb.ClientOptions(
        domain_id=env.domain, logger=LOGGER, zenoh_backlog=samples, zenoh_backlog_bytes=size
    )
    warnings_before = LIBRARY_LOG.count
    async with (
        rmb.connect(env.locator, options=options) as client,
        client.subscribe(topic, schema=schema, buffer=count, adaptive=env.adaptive) as sub,
    ):
        got = Got(count)
        inbox = _inbox_of(client)
        peaks = {"inbox_samples": 0, "inbox_bytes": 0, "queue": 0}

        async def run() -> None:
            async for msg in sub:
                got.bytes += len(msg.data.data)
                got.n += 1
                if got.n == count:
                    got.end = (monotonic(), time.process_time())

        def dropped_before() -> int:
            rejected = client.rejections
            return rejected.get("backlog_overflow", 0) + sum(
                rejected.get(r, 0) for r in DATA_REJECTIONS
            )

        def progress() -> int:
            stats = sub.stats
            return (
                stats.delivered
                + sum(int(getattr(stats, r, 0)) for r in DROP_REASONS)
                + dropped_before()
            )

        def watch() -> None:
            if inbox is not None:
                samples, size = inbox.waiting
                peaks["inbox_samples"] = max(peaks["inbox_samples"], samples)
                peaks["inbox_bytes"] = max(peaks["inbox_bytes"], size)
            peaks["queue"] = max(peaks["queue"], len(sub._queue))

        def fates() -> dict[str, int]:
            counts = subscription_counts(sub)
            rejected = client.rejections
            counts["backlog_overflow"] = rejected.get("backlog_overflow", 0)
            counts["rejected"] = sum(rejected.get(r, 0) for r in DATA_REJECTIONS)
            counts["other_rejections"] = sum(rejected.values()) - (
                counts["backlog_overflow"] + counts["rejected"]
            )
            counts.update({f"peak_{k}": v for k, v in peaks.items()})
            counts["warnings_logged"] = LIBRARY_LOG.count - warnings_before
            return counts

        yield Receiver(got, progress, fates, run, watch)


FACTORIES: Final[dict[str, ClientFactory]] = {"bare": bare, "library": library}


# -- one burst ---------------------------------------------------------------------------


@dataclass
class Sample:
    """One burst: ``received`` (bare) or delivered (library) of ``sent`` messages
    over ``seconds`` (the publisher's first put to the last message), ``cpu``
    seconds of this process's CPU time; the publisher's put time; every fate."""

    client: str
    sent: int
    received: int
    seconds: float
    cpu: float
    put_seconds: float
    fates: dict[str, int] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)

    @property
    def rate(self) -> float:
        return self.received / self.seconds if self.seconds > 0 else 0.0

    @property
    def put_rate(self) -> float:
        return self.sent / self.put_seconds if self.put_seconds > 0 else 0.0

    @property
    def cpu_us(self) -> float:
        return self.cpu / self.received * 1e6 if self.received else 0.0


def problems_of(client: str, sent: int, fates: dict[str, int]) -> list[str]:
    """What is wrong with one burst's fates (messages that vanished)."""
    if client == "bare":
        if fates["received"] != sent:
            return [f"the bare counter received {fates['received']} of {sent} (reliable + BLOCK)"]
        return []
    # inside the subscription: received = delivered + drops + queued (drops are fates here)
    problems = check_fates(fates, may_drop=DROP_REASONS)
    accounted = fates["received"] + fates["backlog_overflow"] + fates["rejected"]
    if accounted != sent:
        problems.append(
            f"{sent - accounted} of {sent} messages unaccounted for (subscription received"
            f" {fates['received']}, inbox overflow {fates['backlog_overflow']},"
            f" rejected {fates['rejected']})"
        )
    return problems


async def measure(env: Env, client: str, kind: Kind, count: int) -> Sample:
    """Subscribe with ``client``, have ``count`` samples put, receive, count."""
    async with FACTORIES[client](env, kind, count) as rx:
        await anyio.sleep(SETTLE)
        got, progress, watch = rx.got, rx.progress, rx.watch
        reply: list[tuple[int, float, float]] = []

        async def publish() -> None:
            reply.append(await anyio.to_thread.run_sync(env.publisher.burst, kind, count))

        cpu_start = time.process_time()
        seen, last = 0, monotonic()
        async with anyio.create_task_group() as tg:
            if rx.run is not None:
                tg.start_soon(rx.run)
            tg.start_soon(publish)
            while True:
                await anyio.sleep(TICK)
                if watch is not None:
                    watch()
                n = progress()
                if n != seen:
                    seen, last = n, monotonic()
                if reply:
                    if n >= reply[0][0]:
                        break
                    if monotonic() - last > IDLE:
                        break  # lost messages: the window ends at the last progress
            tg.cancel_scope.cancel()
        sent, put_start, put_end = reply[0]
        end, cpu_end = got.end or (last, time.process_time())
        fates = rx.fates()
        return Sample(
            client,
            sent,
            got.n,
            end - put_start,
            cpu_end - cpu_start,
            put_end - put_start,
            fates,
            problems_of(client, sent, fates),
        )


# -- the run -----------------------------------------------------------------------------

Samples = dict[Kind, dict[str, list[Sample]]]


async def run_backend(env: Env, backend: Backend, counts: dict[Kind, int], reps: int) -> Samples:
    """A discarded warm-up burst per payload, then ``reps`` rounds of every
    payload and client (the clients' order rotates)."""
    for kind in KINDS:
        for client in CLIENTS:
            await measure(env, client, kind, WARMUP[kind])
    samples: Samples = {kind: {client: [] for client in CLIENTS} for kind in KINDS}
    for rep in range(reps):
        for kind in KINDS:
            order = CLIENTS[rep % 2 :] + CLIENTS[: rep % 2]
            for client in order:
                samples[kind][client].append(await measure(env, client, kind, counts[kind]))
        print(f"  {backend}: repetition {rep + 1}/{reps} done", file=sys.stderr, flush=True)
    return samples


# -- reporting ---------------------------------------------------------------------------


def summarize(samples: list[Sample], payload: int) -> dict[str, float]:
    rate = statistics.median([s.rate for s in samples])
    cpu = [s.cpu_us for s in samples]
    return {
        "msgs_per_s": rate,
        "mb_per_s": rate * payload / 1e6,
        "cpu_us_per_msg": statistics.median(cpu),
        "cpu_us_per_msg_min": min(cpu),
        "cpu_util": statistics.median([s.cpu / s.seconds for s in samples if s.seconds > 0]),
        "put_msgs_per_s": statistics.median([s.put_rate for s in samples]),
        "rate_spread": (max(s.rate for s in samples) - min(s.rate for s in samples)) / rate
        if rate
        else 0.0,
    }


def fmt_rate(value: float) -> str:
    return f"{value / 1e3:.1f} k" if value >= 1e4 else f"{value:.0f}  "


def report(
    backend: Backend, samples: Samples, counts: dict[Kind, int], sizes: dict[Kind, int]
) -> dict[str, Any]:
    """Print the backend's tables and targets; return the summaries."""
    reps = len(samples["string"]["library"])
    table: dict[str, dict[str, dict[str, float]]] = {}
    print(
        f"\n{backend}: bursts of {counts['string']:,} strings / {counts['image']:,} images;"
        f" medians of {reps}"
    )
    print(
        f"  {'case':<20} {'client':<8} {'msgs/s':>9} {'MB/s':>7} {'spread':>6}"
        f" {'CPU us/msg':>10} {'(min)':>8} {'CPU util':>8} {'put msgs/s':>10} {'vs bare':>7}"
    )
    for kind in KINDS:
        table[kind] = {}
        for client in CLIENTS:
            s = table[kind][client] = summarize(samples[kind][client], sizes[kind])
            vs = s["msgs_per_s"] / table[kind]["bare"]["msgs_per_s"]
            print(
                f"  {LABEL[kind]:<20} {client:<8} {fmt_rate(s['msgs_per_s']):>9}"
                f" {s['mb_per_s']:7.1f} {s['rate_spread']:6.0%} {s['cpu_us_per_msg']:10.2f}"
                f" {s['cpu_us_per_msg_min']:8.2f} {s['cpu_util']:8.0%}"
                f" {fmt_rate(s['put_msgs_per_s']):>10} {vs:6.2f}x"
            )

    print("  fate of every message sent (sums over the repetitions):")
    print(
        f"  {'case':<20} {'client':<8} {'sent':>9} {'delivered':>9} {'throttle':>8}"
        f" {'conflated':>9} {'overflow':>8} {'breaker':>7} {'replay':>6} {'queued':>6}"
        f" {'inbox full':>10}"
        f" {'rejected':>8} {'unaccounted':>11}  verdict"
    )
    problems: list[str] = []
    for kind in KINDS:
        for client in CLIENTS:
            runs = samples[kind][client]
            sent = sum(s.sent for s in runs)
            problems += [
                f"{backend} / {LABEL[kind]} / {client}, repetition {i + 1}: {p}"
                for i, s in enumerate(runs)
                for p in s.problems
            ]
            failed = any(s.problems for s in runs)
            if client == "bare":
                received = sum(s.fates["received"] for s in runs)
                print(
                    f"  {LABEL[kind]:<20} {client:<8} {sent:9d} {received:9d}"
                    f" {'-':>8} {'-':>9} {'-':>8} {'-':>7} {'-':>6} {'-':>6} {'-':>10} {'-':>8}"
                    f" {sent - received:11d}  {'FAIL' if failed else 'ok'}"
                )
                continue
            total = {k: sum(s.fates[k] for s in runs) for k in runs[0].fates}
            counted = total["received"] + total["backlog_overflow"] + total["rejected"]
            dropped = sum(total[r] for r in DROP_REASONS) + total["backlog_overflow"]
            verdict = (
                "FAIL" if failed else (f"ok, {dropped} dropped (counted)" if dropped else "ok")
            )
            print(
                f"  {LABEL[kind]:<20} {client:<8} {sent:9d} {total['delivered']:9d}"
                + "".join(
                    f" {total[r]:{w}d}" for r, w in zip(DROP_REASONS, (8, 9, 8, 7, 6), strict=True)
                )
                + f" {total['queued']:6d} {total['backlog_overflow']:10d} {total['rejected']:8d}"
                f" {sent - counted:11d}  {verdict}"
            )
    print("  library, most waiting at once (max over the repetitions):")
    for kind in KINDS:
        runs = samples[kind]["library"]
        inbox = max(s.fates["peak_inbox_samples"] for s in runs)
        inbox_mb = max(s.fates["peak_inbox_bytes"] for s in runs) / 1e6
        queue = max(s.fates["peak_queue"] for s in runs)
        print(
            f"    {LABEL[kind]:<20} zenoh inbox {inbox:,} samples / {inbox_mb:,.1f} MB"
            f" (defaults: {DEFAULTS.zenoh_backlog:,} / {DEFAULTS.zenoh_backlog_bytes / 1e6:.1f} MB),"
            f" subscription queue {queue:,}; library warnings logged:"
            f" {sum(s.fates['warnings_logged'] for s in runs):,}"
        )

    verdicts: dict[str, dict[str, Any]] = {}
    print("  targets (library / bare, medians):")
    for kind in KINDS:
        unit, least = TARGET[kind]
        key = "msgs_per_s" if unit == "msgs/s" else "mb_per_s"
        ratio = table[kind]["library"][key] / table[kind]["bare"][key]
        met = ratio >= least
        verdicts[kind] = {"unit": unit, "ratio": ratio, "target": least, "met": met}
        cpu_ratio = table[kind]["library"]["cpu_us_per_msg"] / table[kind]["bare"]["cpu_us_per_msg"]
        print(
            f"    {LABEL[kind]:<20} {ratio:.2f}x {unit} (target >= {least:.1f}x):"
            f" {'PASS' if met else 'MISS'}   ({cpu_ratio:.2f}x CPU per message)"
        )
    return {"summary": table, "targets": verdicts, "problems": problems}


def versions() -> str:
    return common_versions(("ros-mobile-bridge", "eclipse-zenoh", "anyio", "trio"))


def load() -> str:
    """The 1, 5 and 15 minute load averages: other work on the machine skews the rates."""
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def _terminate(signum: int, frame: FrameType | None) -> None:
    raise SystemExit(128 + signum)  # so that every ``finally`` stops its process


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backend", choices=["asyncio", "trio", "both"], default="both")
    parser.add_argument("--reps", type=int, default=5, help="repetitions (medians are reported)")
    parser.add_argument("--strings", type=int, default=400_000, help="Strings per burst")
    parser.add_argument("--images", type=int, default=1_000, help="Images per burst")
    parser.add_argument(
        "--backlog",
        choices=["fit", "default"],
        default="fit",
        help="fit: the library's zenoh inbox holds one burst; default: ClientOptions' defaults",
    )
    parser.add_argument("--json", type=Path, help="also write every sample and summary here")
    parser.add_argument(
        "--no-adaptive",
        action="store_true",
        help="subscribe with adaptive=False: no throttle drops when the event loop lags",
    )
    parser.add_argument("--strict", action="store_true", help="a missed target fails the run")
    args = parser.parse_args()
    if args.reps < 1 or args.strings < 1 or args.images < 1:
        parser.error("--reps, --strings and --images must be positive")
    backends: list[Backend] = ["asyncio", "trio"] if args.backend == "both" else [args.backend]
    counts: dict[Kind, int] = {"string": args.strings, "image": args.images}
    signal.signal(signal.SIGTERM, _terminate)

    out: dict[str, Any] = {"versions": versions(), "args": {**vars(args), "json": str(args.json)}}
    with ExitStack() as stack:
        locator, which = router(stack)
        publisher = Publisher(locator, DOMAIN)
        stack.callback(publisher.close)
        print(versions())
        print(
            f"{platform.machine()}, {len(os.sched_getaffinity(0))} CPUs; router ({which}) and"
            f" publisher in subprocesses on {locator}, domain {DOMAIN}; zenoh inbox: {args.backlog};"
            f" adaptive throttle: {'off' if args.no_adaptive else 'on'};"
            " 1 MB = 1e6 bytes of CDR payload"
        )
        print(f"load average before: {load()}")
        sizes = publisher.sizes
        env = Env(locator, DOMAIN, publisher, args.backlog, not args.no_adaptive)
        for backend in backends:
            samples = anyio.run(run_backend, env, backend, counts, args.reps, backend=backend)
            out[backend] = report(backend, samples, counts, sizes)
            out[backend]["load_after"] = load()
            print(f"  load average after {backend}: {load()} (other processes share the CPUs)")
            out[backend]["samples"] = {
                kind: {
                    client: [{**asdict(s), "rate": s.rate, "cpu_us": s.cpu_us} for s in runs]
                    for client, runs in by_client.items()
                }
                for kind, by_client in samples.items()
            }
    out["counts"] = counts
    out["sizes"] = sizes
    problems = [p for backend in backends for p in out[backend]["problems"]]
    misses = [
        f"{backend} / {LABEL[kind]}: {t['ratio']:.2f}x {t['unit']} < {t['target']:.1f}x"
        for backend in backends
        for kind, t in out[backend]["targets"].items()
        if not t["met"]
    ]
    out["problems"], out["misses"] = problems, misses
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
        print(f"\nwrote {args.json}")
    if problems:
        print("\nFAILED: messages vanished:", file=sys.stderr)
        for problem in problems:
            print(f"  {problem}", file=sys.stderr)
    if misses:
        print(f"\nmissed targets{' (--strict)' if args.strict else ''}:", file=sys.stderr)
        for miss in misses:
            print(f"  {miss}", file=sys.stderr)
    if problems or (misses and args.strict):
        raise SystemExit(1)


if __name__ == "__main__":
    main()
