"""Reliability benchmark: control latency under image load, and the cost of throttling.

    .venv/bin/python bench/bench_reliability.py [--backend asyncio|trio|both]
        [--publishes 500] [--seconds 3] [--reps 3] [--full-hz 2000]
        [--only latency|throttle] [--malloc default|steady] [--json PATH] [--trace] [--profile]

The server is the official Foxglove SDK (``foxglove-sdk``) in a subprocess,
``bench/_peer.py reliability``, so its CPU never shares the client's GIL. It
streams ``/bench/image`` (``sensor_msgs/msg/Image``, 640x480 rgb8, 921,652
bytes of CDR) at a settable rate and accepts client publishing; its listener
stamps every ``/cmd_vel`` message with ``time.time_ns()`` on receipt.

1. **Control latency.** One client connects (``advertise_settle=0``),
   ``await robot.advertise("/cmd_vel", ...)``, optionally subscribes to the
   image and consumes it (every frame decoded, ``msg.data.data`` touched),
   then publishes N Twists 15-25 ms apart (seeded jitter, so the publishes do
   not phase-lock with the image stream). Each Twist carries its sequence
   number in ``linear.y``. Latency = the server's receipt stamp minus
   ``time.time_ns()`` taken just before ``await robot.publish(...)``: one
   clock (CLOCK_REALTIME) in both processes. Loads: none, a 30 Hz camera, and
   "full rate" (the server paced at ``--full-hz``, above what the client can
   take, with an 8-message per-client backlog: the server drops the excess and
   the client is saturated). Cases: ``priority="control"`` and ``"data"`` on
   each load, and control on a second connection of the same event loop
   under full load. In every window an idle client in its own process
   (``_peer.py publisher``, no subscription) publishes to the same server:
   the baseline of what the server and the machine add. The bench also
   times each frame entering the client's outbox and being written to the
   socket (by wrapping ``put_control``/``put_data`` and the backend's
   ``send``), how late a 1 ms sleep in the server process wakes, and this
   process's garbage-collector pauses.
2. **Throttling cost.** Client CPU (``time.process_time()`` of this process,
   user + system) per 1000 image frames that reached the subscription
   (``sub.stats.received``), for ``subscribe(max_hz=5)`` against an
   unthrottled subscription on the same stream. Also: the raw transport (the
   library's WebSocket in a receive loop, nothing above it), a connected
   client with no subscription (the fixed cost per second), and
   ``save_bandwidth=True`` at the same ``max_hz`` (the server stops sending
   between deliveries).

``--trace`` adds a pass with every event-loop task step timed (wall and
CPU), attributing the client-side wait of the slowest control publishes to
the tasks that ran in it, and (Linux) watches the server's socket receive
queue in ``/proc/net/tcp``. ``--profile`` samples where the CPU of an
unthrottled and a ``max_hz=5`` window goes. See ``bench/README.md``.
"""

from __future__ import annotations

import argparse
import bisect
import gc
import json
import os
import platform
import random
import resource
import signal
import statistics
import struct
import subprocess
import sys
import time
from collections import Counter
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import (
    AbstractAsyncContextManager,
    AsyncExitStack,
    ExitStack,
    asynccontextmanager,
    contextmanager,
    suppress,
)
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import FrameType
from typing import Any, Final, Literal, TypeVar

import anyio
import anyio.to_thread

import ros_mobile_bridge as rmb
from ros_mobile_bridge.transport import connect_websocket

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import client_internals
from _peer import CMD_TOPIC, IDLE_TOPIC, IMAGE_TOPIC, TWIST_TYPE
from bench_foxglove import _where, steady_malloc, versions

T = TypeVar("T")
Backend = Literal["asyncio", "trio"]
Priority = Literal["control", "data"]
PEER: Final = Path(__file__).resolve().parent / "_peer.py"
BACKLOG: Final = 8
"""The server's per-client queue: past it the oldest image is dropped."""
CAMERA_HZ: Final = 30.0
THROTTLE_HZ: Final = 5.0
SETTLE: Final = 0.5
"""Seconds of image load before a measurement starts (steady state)."""
SPACING: Final = (0.015, 0.025)
"""Seconds between two publishes (uniform; a 20 ms mean)."""
TARGET_P99_MS: Final = 5.0
TARGET_THROTTLE: Final = 0.10
SUBPROTOCOL: Final = "foxglove.sdk.v1.1"
_MESSAGE_SEQ: Final = struct.Struct("<d")
_SEQ_OFFSET: Final = 1 + 4 + 4 + 8
"""In a client message-data frame: opcode, channel id, CDR header, linear.x."""


# -- the server process ---------------------------------------------------------------


class Peer:
    """``bench/_peer.py reliability`` in a subprocess, driven over its pipes.

    Its methods block the calling thread for a pipe round trip: the bench
    calls them through :func:`blocking`, outside the measured windows."""

    def __init__(self, backlog: int = BACKLOG) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER), "reliability", str(backlog)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self._in, self._out = self.proc.stdin, self.proc.stdout
        self.url = f"ws://127.0.0.1:{self._ask('', 'port')[0]}"

    def _ask(self, line: str, expected: str) -> list[str]:
        if line:
            self._in.write(line + "\n")
            self._in.flush()
        words = self._out.readline().split()
        if not words or words[0] != expected:
            raise RuntimeError(f"server: {' '.join(words) or 'exited'}")
        return words[1:]

    def stream(self, rate: float) -> None:
        """Stream the image at ``rate`` per second from now on (0 stops)."""
        self._ask(f"stream {rate}", "ok")

    def probe_start(self) -> None:
        """Start timing the server process's own wake-ups (1 ms sleeps)."""
        self._ask("probe start", "ok")

    def probe_stop(self) -> list[float]:
        """How late each of the server's 1 ms sleeps woke since
        :meth:`probe_start`, in ms."""
        return [int(us) / 1e3 for us in self._ask("probe stop", "probe")]

    def commands(self, topic: str = CMD_TOPIC) -> dict[int, int]:
        """Sequence number -> server receipt time (ns) of the Twists received
        on ``topic`` since the last call for it."""
        words = self._ask(f"commands {topic}", "commands")
        out: dict[int, int] = {}
        for word in words[1:]:
            seq, ns = word.split(":")
            out.setdefault(int(seq), int(ns))
        return out

    def close(self) -> None:
        if self.proc.poll() is None:
            try:
                self._in.write("quit\n")
                self._in.close()
                self.proc.wait(timeout=10)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait()


class IdlePublisher:
    """``bench/_peer.py publisher``: a second client in its own process, with
    no subscription and nothing else to do, publishing control frames to the
    same server during the same window (the baseline of the server and the
    machine)."""

    def __init__(self, url: str, count: int, seed: int) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER), "publisher", url, str(count), str(seed)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self._in, self._out = self.proc.stdin, self.proc.stdout
        if self._out.readline().strip() != "ready":
            raise RuntimeError("the idle publisher did not start")

    def go(self) -> None:
        self._in.write("go\n")
        self._in.flush()

    def sent(self) -> dict[int, int]:
        """Sequence number -> ``time.time_ns()`` before its send (blocks until done)."""
        words = self._out.readline().split()
        self.proc.wait(timeout=10)
        if not words or words[0] != "sent":
            raise RuntimeError(f"idle publisher: {' '.join(words) or 'exited'}")
        return {int(seq): int(ns) for seq, ns in (w.split(":") for w in words[1:])}


async def blocking(fn: Callable[..., T], *args: Any) -> T:
    """Run a blocking call (a pipe round trip, a process start) in a worker
    thread: blocking the event loop would show up as loop lag, and the
    client's adaptive throttle would answer it by dropping frames."""
    return await anyio.to_thread.run_sync(fn, *args)


# -- the image consumer ----------------------------------------------------------------


@dataclass
class Consumed:
    frames: int = 0
    bytes: int = 0


async def consume(sub: rmb.Subscription, into: Consumed) -> None:
    """Decode every message and touch its pixels, as an app showing them would."""
    async for msg in sub:
        into.bytes += len(msg.data.data)
        into.frames += 1


# -- where a control frame spends its time in the client -------------------------------


@dataclass
class Sent:
    """Where one published frame went in the client: when it entered the
    outbox, when the client started and finished writing it to the socket,
    and which task wrote it."""

    queued_ns: int = 0
    start_ns: int = 0
    end_ns: int = 0
    task: str = ""


def _task_name() -> str:
    try:
        return anyio.get_current_task().name or "?"
    except RuntimeError:
        return "?"


def _twist_seq(message: object) -> int:
    """The sequence number of a client message-data frame carrying one of our
    Twists (CDR), else 0."""
    if isinstance(message, bytes) and len(message) >= _SEQ_OFFSET + 8 and message[0] == 1:
        return int(_MESSAGE_SEQ.unpack_from(message, _SEQ_OFFSET)[0])
    return 0


@contextmanager
def trace_sends(robot: rmb.Client, into: dict[int, Sent]) -> Iterator[bool]:
    """Time every published Twist (by sequence number) as it enters the
    client's outbox and as the backend writes it, by wrapping the outbox's
    ``put_control`` / ``put_data`` and the backend's ``send`` on this
    connection. Bench-only instrumentation, a few microseconds per frame;
    yields False (recording nothing) if the client's internals have moved."""
    backend, outbox = client_internals(robot)
    send = getattr(backend, "send", None)
    put_control = getattr(outbox, "put_control", None)
    put_data = getattr(outbox, "put_data", None)
    if send is None or put_control is None or put_data is None:
        yield False
        return
    clock = time.time_ns

    def queued(message: object) -> None:
        if seq := _twist_seq(message):
            into.setdefault(seq, Sent()).queued_ns = clock()

    def traced_put_control(key: Any, message: Any) -> None:
        queued(message)
        put_control(key, message)

    async def traced_put_data(key: Any, message: Any) -> None:
        await put_data(key, message)
        queued(message)

    async def traced_send(message: Any) -> None:
        start = clock()
        await send(message)
        if seq := _twist_seq(message):
            sent = into.setdefault(seq, Sent())
            sent.start_ns, sent.end_ns, sent.task = start, clock(), _task_name()

    backend.send = traced_send
    outbox.put_control = traced_put_control
    outbox.put_data = traced_put_data
    try:
        yield True
    finally:
        for obj, name in ((backend, "send"), (outbox, "put_control"), (outbox, "put_data")):
            with suppress(AttributeError):
                delattr(obj, name)


@contextmanager
def gc_pauses(into: list[float]) -> Iterator[None]:
    """Append the length (ms) of every garbage collection in the block."""
    started = 0

    def callback(phase: str, info: dict[str, int]) -> None:
        nonlocal started
        if phase == "start":
            started = time.perf_counter_ns()
        elif started:
            into.append((time.perf_counter_ns() - started) / 1e6)

    gc.callbacks.append(callback)
    try:
        yield
    finally:
        gc.callbacks.remove(callback)


Step = tuple[int, int, str, int]


class StepTrace:
    """Every task step of the event loop: ``(start_ns, end_ns, task,
    cpu_ns)``, wall times in ``time.time_ns()``, ``cpu_ns`` the thread's CPU
    time in the step (less than the wall time when the OS ran something else
    meanwhile). ``--trace`` only: it slows the loop down."""

    def __init__(self) -> None:
        self.steps: list[Step] = []

    @contextmanager
    def installed(self, backend: Backend) -> Iterator[None]:
        if backend == "trio":
            with self._trio():
                yield
        else:
            with self._asyncio():
                yield

    @contextmanager
    def _trio(self) -> Iterator[None]:
        import trio

        steps = self.steps
        clock, cpu_clock = time.time_ns, time.thread_time_ns

        class Steps(trio.abc.Instrument):
            def __init__(self) -> None:
                self.start = self.cpu = 0

            def before_task_step(self, task: Any) -> None:
                self.start, self.cpu = clock(), cpu_clock()

            def after_task_step(self, task: Any) -> None:
                steps.append((self.start, clock(), task.name, cpu_clock() - self.cpu))

        instrument = Steps()
        trio.lowlevel.add_instrument(instrument)
        try:
            yield
        finally:
            trio.lowlevel.remove_instrument(instrument)

    @contextmanager
    def _asyncio(self) -> Iterator[None]:
        import asyncio.events

        steps = self.steps
        clock, cpu_clock = time.time_ns, time.thread_time_ns
        handle_cls: Any = asyncio.events.Handle
        original = handle_cls._run

        def run(handle: Any) -> None:
            start, cpu = clock(), cpu_clock()
            original(handle)
            cpu = cpu_clock() - cpu
            callback = handle._callback
            owner = getattr(callback, "__self__", None)
            if isinstance(owner, asyncio.Task):
                name = owner.get_name()
            else:
                name = getattr(callback, "__qualname__", type(callback).__name__)
            steps.append((start, clock(), name, cpu))

        handle_cls._run = run
        try:
            yield
        finally:
            handle_cls._run = original


@dataclass
class Share:
    """What one task did inside the attributed windows (ns)."""

    wall: float = 0.0
    cpu: float = 0.0
    longest: int = 0
    longest_cpu: int = 0


def attribute(steps: list[Step], windows: list[tuple[int, int]]) -> tuple[dict[str, Share], int]:
    """The task steps inside the (start, end) windows, by task (a step cut
    by a window's edge counts pro rata), and the windows' total length (ns).
    Time in no step is the loop polling for I/O, or the process not running."""
    steps = sorted(steps)
    starts = [step[0] for step in steps]
    shares: dict[str, Share] = {}
    length = 0
    for begin, end in windows:
        length += end - begin
        i = max(bisect.bisect_left(starts, begin) - 1, 0)
        while i < len(steps) and steps[i][0] < end:
            s, e, name, cpu = steps[i]
            overlap = min(e, end) - max(s, begin)
            if overlap > 0:
                share = shares.setdefault(name, Share())
                share.wall += overlap
                share.cpu += cpu * overlap / max(e - s, 1)
                if e - s > share.longest:
                    share.longest, share.longest_cpu = e - s, cpu
            i += 1
    return shares, length


# -- 1. control latency ---------------------------------------------------------------


@dataclass
class Record:
    """One publish, all in ``time.time_ns()``: the stamp just before
    ``publish``, the frame entering the outbox, the client's write of the
    frame (start and end) and the writing task (0 and "" when not traced),
    the server's receipt (0 when lost)."""

    seq: int
    publish_ns: int
    queued_ns: int
    write_start_ns: int
    write_end_ns: int
    task: str
    receipt_ns: int


@dataclass
class LatencySample:
    """One latency case: every publish of one connection."""

    load: str
    priority: str
    publishes: int
    connection: str
    """``"same"``: published by the client that consumes the images;
    ``"own"``: by a second connection of the same event loop."""
    records: list[Record]
    call_ms: list[float]
    """How long each ``await robot.publish(...)`` took."""
    lag_ms: list[float]
    """How late the publishing task woke for each slot (event-loop lag)."""
    image_hz: float
    """Image frames routed to the subscription per second of the window."""
    delivered_hz: float
    """Image messages the consumer got per second of the window."""
    adaptive_drops: int
    """Frames the adaptive throttle dropped (the subscription has no max_hz)."""
    breaker_drops: int
    cpu_util: float
    overflow: int
    coalesced: int
    server_late_ms: list[float]
    """How late the server process's 1 ms sleeps woke during the case."""
    gc_ms: list[float]
    """This process's garbage-collector pauses during the case."""
    idle_ms: list[float]
    """Latency of the idle publisher's control frames in the same window."""

    @property
    def latency_ms(self) -> list[float]:
        """Server receipt minus the stamp before ``publish``, per received publish."""
        return [(r.receipt_ns - r.publish_ns) / 1e6 for r in self.records if r.receipt_ns]

    @property
    def queued_ms(self) -> list[float]:
        """The stamp before ``publish`` to the client starting to write the frame."""
        return [(r.write_start_ns - r.publish_ns) / 1e6 for r in self.records if r.write_start_ns]

    @property
    def enqueue_ms(self) -> list[float]:
        """The stamp before ``publish`` to the frame entering the outbox."""
        return [(r.queued_ns - r.publish_ns) / 1e6 for r in self.records if r.queued_ns]

    @property
    def outbox_ms(self) -> list[float]:
        """The frame entering the outbox to the client starting to write it."""
        return [
            (r.write_start_ns - r.queued_ns) / 1e6
            for r in self.records
            if r.queued_ns and r.write_start_ns
        ]

    @property
    def wire_ms(self) -> list[float]:
        """The client's write done to the server's receipt stamp."""
        return [
            (r.receipt_ns - r.write_end_ns) / 1e6
            for r in self.records
            if r.write_end_ns and r.receipt_ns
        ]

    @property
    def sent_by(self) -> dict[str, int]:
        return dict(Counter(r.task for r in self.records if r.task))

    @property
    def lost(self) -> int:
        return sum(1 for r in self.records if not r.receipt_ns)


def pct(values: list[float], q: float) -> float:
    """The ``q``-quantile (0..1) by the nearest-rank method; NaN when empty."""
    if not values:
        return float("nan")
    ordered = sorted(values)
    rank = max(int(-(-q * len(ordered) // 1)), 1)  # ceil(q * n), at least 1
    return ordered[min(rank, len(ordered)) - 1]


async def latency_case(
    peer: Peer,
    backend: Backend,
    load: str,
    rate: float,
    priority: Priority,
    publishes: int,
    first_seq: int,
    steps: StepTrace | None = None,
    own_connection: bool = False,
) -> LatencySample:
    """Publish ``publishes`` Twists on ``/cmd_vel`` while the same client
    consumes the image stream at ``rate`` (0: no subscription). With
    ``own_connection`` the Twists go out on a second connection of this
    event loop, one with no subscription."""
    options = rmb.ClientOptions(advertise_settle=0)
    rng = random.Random(first_seq)
    send_ns: dict[int, int] = {}
    sent: dict[int, Sent] = {}
    call_ms: list[float] = []
    lag_ms: list[float] = []
    gc_ms: list[float] = []
    consumed = Consumed()
    sub: rmb.Subscription | None = None
    async with AsyncExitStack() as stack:
        robot = await stack.enter_async_context(
            rmb.connect(peer.url, protocol="foxglove-ws", options=options)
        )
        publisher = robot
        if own_connection:
            publisher = await stack.enter_async_context(
                rmb.connect(peer.url, protocol="foxglove-ws", options=options)
            )
        await publisher.advertise(CMD_TOPIC, TWIST_TYPE)
        # one unmeasured publish (seq 0: the server ignores it) warms the encoder
        await publisher.publish(CMD_TOPIC, TWIST_TYPE, {"linear": {"x": 0.1}}, priority=priority)
        if rate > 0:
            # adaptive=False: every frame is decoded, whatever the loop's lag
            sub = await stack.enter_async_context(robot.subscribe(IMAGE_TOPIC, adaptive=False))
            await sub.wait_active()
        async with anyio.create_task_group() as tg:
            if sub is not None:
                tg.start_soon(consume, sub, consumed)
                await blocking(peer.stream, rate)
                await anyio.sleep(SETTLE)
            idle = await blocking(IdlePublisher, peer.url, publishes, first_seq)
            await blocking(peer.probe_start)
            idle.go()
            with ExitStack() as instruments:  # removed again before the teardown
                if steps is not None:
                    instruments.enter_context(steps.installed(backend))
                instruments.enter_context(trace_sends(publisher, sent))
                instruments.enter_context(gc_pauses(gc_ms))
                received0 = sub.stats.received if sub is not None else 0
                delivered0 = sub.stats.delivered if sub is not None else 0
                cpu0, wall0 = time.process_time(), time.perf_counter()
                due = anyio.current_time()
                for i in range(publishes):
                    due += rng.uniform(*SPACING)
                    await anyio.sleep_until(due)
                    lag_ms.append((anyio.current_time() - due) * 1e3)
                    seq = first_seq + i
                    data = {"linear": {"x": 0.1, "y": float(seq)}, "angular": {"z": 0.2}}
                    start = send_ns[seq] = time.time_ns()
                    await publisher.publish(CMD_TOPIC, TWIST_TYPE, data, priority=priority)
                    call_ms.append((time.time_ns() - start) / 1e6)
                await anyio.sleep(0.05)  # the last frames leave
                cpu, wall = time.process_time() - cpu0, time.perf_counter() - wall0
            server_late = await blocking(peer.probe_stop)
            idle_sent = await blocking(idle.sent)
            if sub is not None:
                await blocking(peer.stream, 0)
            tg.cancel_scope.cancel()
        stats = sub.stats if sub is not None else None
        image_hz = (stats.received - received0) / wall if stats is not None else 0.0
        delivered_hz = (stats.delivered - delivered0) / wall if stats is not None else 0.0
        overflow = stats.dropped_overflow if stats is not None else 0
        adaptive_drops = stats.dropped_throttle if stats is not None else 0
        breaker_drops = getattr(stats, "dropped_breaker", 0)
        outbox = client_internals(publisher)[1]
        coalesced = outbox.coalesced if outbox is not None else 0
    received: dict[int, int] = {}
    for _ in range(20):  # the teardown confirmed delivery; this is a safety net
        received.update(await blocking(peer.commands))
        if all(seq in received for seq in send_ns):
            break
        await anyio.sleep(0.05)
    idle_received = await blocking(peer.commands, IDLE_TOPIC)
    idle_ms = [(idle_received[k] - v) / 1e6 for k, v in idle_sent.items() if k in idle_received]
    records = []
    for seq, start in send_ns.items():
        w = sent.get(seq, Sent())
        records.append(
            Record(seq, start, w.queued_ns, w.start_ns, w.end_ns, w.task, received.get(seq, 0))
        )
    return LatencySample(
        load,
        priority,
        publishes,
        "own" if own_connection else "same",
        records,
        call_ms,
        lag_ms,
        image_hz,
        delivered_hz,
        adaptive_drops,
        breaker_drops,
        cpu / wall,
        overflow,
        coalesced,
        server_late,
        gc_ms,
        idle_ms,
    )


# -- 2. throttling cost ----------------------------------------------------------------


@dataclass
class ThrottleSample:
    load: str
    client: str
    seconds: float
    cpu: float
    frames: int
    delivered: int
    faults: int

    @property
    def cpu_per_1000(self) -> float:
        return self.cpu / self.frames * 1000 if self.frames else float("nan")


Counters = tuple[Callable[[], int], Callable[[], int]]
"""(frames received, frames delivered) so far."""


@asynccontextmanager
async def library_receiver(
    url: str, max_hz: float | None, *, save_bandwidth: bool = False
) -> AsyncIterator[Counters]:
    """A subscribed, consuming client; yields (frames received, frames delivered)."""
    consumed = Consumed()
    async with (
        rmb.connect(url, protocol="foxglove-ws") as robot,
        robot.subscribe(
            IMAGE_TOPIC, max_hz=max_hz, adaptive=False, save_bandwidth=save_bandwidth
        ) as sub,
        anyio.create_task_group() as tg,
    ):
        await sub.wait_active()
        tg.start_soon(consume, sub, consumed)
        yield (lambda: sub.stats.received), (lambda: sub.stats.delivered)
        tg.cancel_scope.cancel()


@asynccontextmanager
async def transport_receiver(url: str, max_hz: float | None) -> AsyncIterator[Counters]:
    """The library's own WebSocket in a raw loop counting binary frames (no
    Foxglove parsing, no routing, no decoding): what receiving alone costs."""
    ws = await connect_websocket(url, subprotocols=(SUBPROTOCOL,), max_size=None)
    count = Consumed()
    try:
        while True:  # subscribe to the image channel (subscription id 1)
            message = await ws.receive()
            if isinstance(message, str) and (op := json.loads(message)).get("op") == "advertise":
                ids = [ch["id"] for ch in op["channels"] if ch["topic"] == IMAGE_TOPIC]
                if ids:
                    sub = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": ids[0]}]}
                    await ws.send(json.dumps(sub))
                    break

        async def run() -> None:
            while True:
                message = await ws.receive()
                if not isinstance(message, str):
                    count.frames += 1

        async with anyio.create_task_group() as tg:
            tg.start_soon(run)
            yield (lambda: count.frames), (lambda: 0)
            tg.cancel_scope.cancel()
    finally:
        await ws.aclose()


Receiver = Callable[[str, float | None], AbstractAsyncContextManager[Counters]]


@asynccontextmanager
async def idle_receiver(url: str, max_hz: float | None) -> AsyncIterator[Counters]:
    """A connected client with no subscription: the library's fixed cost
    (keep-alive, lag monitor), which a slow topic's per-frame figure carries."""
    async with rmb.connect(url, protocol="foxglove-ws"):
        yield (lambda: 0), (lambda: 0)


@asynccontextmanager
async def bandwidth_receiver(url: str, max_hz: float | None) -> AsyncIterator[Counters]:
    """The library's ``save_bandwidth=True`` mode at ``max_hz``: it
    unsubscribes after each delivery and subscribes again when the next is
    due, so the server stops sending instead of the client dropping."""
    async with library_receiver(url, max_hz, save_bandwidth=True) as counters:
        yield counters


async def throttle_case(
    peer: Peer, load: str, rate: float, client: str, seconds: float
) -> ThrottleSample:
    receivers: dict[str, Receiver] = {
        "transport": transport_receiver,
        IDLE_CLIENT: idle_receiver,
        BANDWIDTH_CLIENT: bandwidth_receiver,
    }
    receiver = receivers.get(client, library_receiver)
    max_hz = THROTTLE_HZ if "max_hz" in client else None
    async with receiver(peer.url, max_hz) as (received, delivered):
        await blocking(peer.stream, rate)
        await anyio.sleep(SETTLE)
        r0, d0 = received(), delivered()
        f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
        c0, w0 = time.process_time(), time.perf_counter()
        await anyio.sleep(seconds)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        sample = ThrottleSample(
            load,
            client,
            wall,
            cpu,
            received() - r0,
            delivered() - d0,
            resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0,
        )
        await blocking(peer.stream, 0)
    return sample


# -- the run ---------------------------------------------------------------------------


@dataclass
class Result:
    latency: list[LatencySample] = field(default_factory=list)
    throttle: list[ThrottleSample] = field(default_factory=list)
    trace: Traced | None = None
    profiles: dict[str, Profile] = field(default_factory=dict)


IDLE_CLIENT: Final = "library, no sub"
BANDWIDTH_CLIENT: Final = f"library max_hz={THROTTLE_HZ:g} save_bandwidth"
THROTTLE_CLIENTS: Final = (
    "library",
    f"library max_hz={THROTTLE_HZ:g}",
    "transport",
    IDLE_CLIENT,
    BANDWIDTH_CLIENT,
)


@dataclass(frozen=True)
class Settings:
    publishes: int
    seconds: float
    reps: int
    full_hz: float
    latency: bool
    throttle: bool
    trace: bool
    profile: bool


async def run_backend(peer: Peer, backend: Backend, settings: Settings, first_seq: int) -> Result:
    """Every latency case, then ``reps`` interleaved throttling windows per
    client and load, then the ``--trace`` pass."""
    result = Result()
    full = settings.full_hz
    loads = [("none", 0.0), (f"camera {CAMERA_HZ:g} Hz", CAMERA_HZ), ("full rate", full)]
    seq = first_seq
    cases: list[tuple[str, float, Priority, bool]] = [
        (load, rate, priority, False) for load, rate in loads for priority in ("control", "data")
    ]
    cases.append(("full rate", full, "control", True))
    for load, rate, priority, own in cases if settings.latency else []:
        sample = await latency_case(
            peer, backend, load, rate, priority, settings.publishes, seq, own_connection=own
        )
        seq += settings.publishes
        result.latency.append(sample)
        print(
            f"  {backend}: latency, load {load}, {priority}, {sample.connection} connection",
            file=sys.stderr,
            flush=True,
        )
    for rep in range(settings.reps if settings.throttle else 0):
        for load, rate in loads[1:]:
            clients = list(THROTTLE_CLIENTS)
            clients = clients[rep % len(clients) :] + clients[: rep % len(clients)]
            for client in clients:
                sample_t = await throttle_case(peer, load, rate, client, settings.seconds)
                result.throttle.append(sample_t)
        print(
            f"  {backend}: throttle, repetition {rep + 1}/{settings.reps}",
            file=sys.stderr,
            flush=True,
        )
    if settings.trace:
        result.trace = await trace_tail(peer, backend, full, settings.publishes, seq)
    if settings.profile:
        for client in ("library", f"library max_hz={THROTTLE_HZ:g}"):
            result.profiles[client] = await profile_throttle(peer, full, client, settings.seconds)
    return result


@dataclass
class Profile:
    """SIGPROF samples (CPU time, user + system) of one throttling window:
    the function each sample interrupted, and every function on its stack."""

    sample: ThrottleSample
    own: Counter[str]
    inclusive: Counter[str]


async def profile_throttle(peer: Peer, rate: float, client: str, seconds: float) -> Profile:
    """One throttling window of ``client`` under a statistical profiler."""
    own: Counter[str] = Counter()
    inclusive: Counter[str] = Counter()

    def sample(signum: int, frame: FrameType | None) -> None:
        if frame is None:
            return
        own[_where(frame)] += 1
        seen: set[str] = set()
        f: FrameType | None = frame
        while f is not None:
            seen.add(_where(f))
            f = f.f_back
        inclusive.update(seen)

    previous = signal.signal(signal.SIGPROF, sample)
    signal.setitimer(signal.ITIMER_PROF, 0.0005, 0.0005)
    try:
        result = await throttle_case(peer, "full rate", rate, client, seconds)
    finally:
        signal.setitimer(signal.ITIMER_PROF, 0, 0)
        signal.signal(signal.SIGPROF, previous)
    return Profile(result, own, inclusive)


class RxQueueWatch:
    """``_peer.py rxqueue`` in a subprocess (Linux): the server's socket
    receive queues over time, as ``(time_ns, bytes unread)`` changes."""

    def __init__(self, url: str) -> None:
        port = url.rsplit(":", 1)[1]
        self.proc = subprocess.Popen(
            [sys.executable, str(PEER), "rxqueue", port],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        if self.proc.stdout.readline().strip() != "ready":
            raise RuntimeError("rxqueue watcher did not start")

    def stop(self) -> list[tuple[int, int]]:
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self.proc.stdin.write("\n")
        self.proc.stdin.flush()
        words = self.proc.stdout.readline().split()
        self.proc.wait(timeout=10)
        unread: dict[str, int] = {}
        out: list[tuple[int, int]] = []
        for word in words[1:]:  # the total over every connection to the server
            ns, rest = word.split(":", 1)
            remote, size = rest.rsplit(":", 1)
            unread[remote] = int(size)
            out.append((int(ns), sum(unread.values())))
        return out


def unread_intervals(changes: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The (start, end) stretches in which the server left received bytes unread."""
    out: list[tuple[int, int]] = []
    start: int | None = None
    for ns, size in changes:
        if size > 0 and start is None:
            start = ns
        elif size == 0 and start is not None:
            out.append((start, ns))
            start = None
    return out


def overlap(intervals: list[tuple[int, int]], begin: int, end: int) -> int:
    return sum(max(0, min(e, end) - max(s, begin)) for s, e in intervals)


@dataclass
class Traced:
    sample: LatencySample
    steps: list[Step]
    unread: list[tuple[int, int]]
    """The server's unread bytes over time (empty when not watched)."""


async def trace_tail(
    peer: Peer, backend: Backend, rate: float, publishes: int, first_seq: int
) -> Traced:
    """Control publishes under full load with every task step timed and, on
    Linux, the server's socket receive queue watched."""
    steps = StepTrace()
    watch = RxQueueWatch(peer.url) if sys.platform == "linux" else None
    try:
        sample = await latency_case(
            peer, backend, "full rate", rate, "control", publishes, first_seq, steps
        )
    finally:
        unread = watch.stop() if watch is not None else []
    return Traced(sample, steps.steps, unread)


# -- reporting ---------------------------------------------------------------------------


def fmt(value: float, width: int = 7) -> str:
    return f"{value:{width}.2f}" if value == value else f"{'-':>{width}}"


def report_latency(backend: Backend, samples: list[LatencySample]) -> list[dict[str, Any]]:
    rows: list[dict[str, Any]] = []
    for s in samples:
        rows.append(
            {
                "load": s.load,
                "priority": s.priority,
                "connection": s.connection,
                "received": len(s.latency_ms),
                "p50": pct(s.latency_ms, 0.5),
                "p90": pct(s.latency_ms, 0.9),
                "p99": pct(s.latency_ms, 0.99),
                "max": max(s.latency_ms, default=float("nan")),
                "lost": s.lost,
                "idle_p50": pct(s.idle_ms, 0.5),
                "idle_p99": pct(s.idle_ms, 0.99),
                "idle_lost": s.publishes - len(s.idle_ms),
                "image_hz": s.image_hz,
                "delivered_hz": s.delivered_hz,
                "adaptive_drops": s.adaptive_drops,
                "breaker_drops": s.breaker_drops,
                "cpu_util": s.cpu_util,
                "overflow": s.overflow,
                "coalesced": s.coalesced,
                "queued_p50": pct(s.queued_ms, 0.5),
                "queued_p99": pct(s.queued_ms, 0.99),
                "enqueue_p50": pct(s.enqueue_ms, 0.5),
                "enqueue_p99": pct(s.enqueue_ms, 0.99),
                "outbox_p50": pct(s.outbox_ms, 0.5),
                "outbox_p99": pct(s.outbox_ms, 0.99),
                "wire_p50": pct(s.wire_ms, 0.5),
                "wire_p99": pct(s.wire_ms, 0.99),
                "call_p99": pct(s.call_ms, 0.99),
                "lag_p99": pct(s.lag_ms, 0.99),
                "server_late_p99": pct(s.server_late_ms, 0.99),
                "gc_max": max(s.gc_ms, default=0.0),
                "gc_count": len(s.gc_ms),
                "sent_by": s.sent_by,
            }
        )
    print(f"\n{backend}: control latency, publish() called -> server receipt stamp (ms)")
    print(
        f"  {'load':<15} {'priority':<8} {'conn':<4} {'n':>4} {'p50':>7} {'p90':>7} {'p99':>7}"
        f" {'max':>7} {'lost':>4} {'images/s':>8} {'decoded/s':>9} {'client CPU':>10} |"
        f" {'idle client p50':>15}"
        f" {'p99':>6}"
    )
    for r in rows:
        print(
            f"  {r['load']:<15} {r['priority']:<8} {r['connection']:<4} {r['received']:4d}"
            f" {fmt(r['p50'])}"
            f" {fmt(r['p90'])} {fmt(r['p99'])} {fmt(r['max'])} {r['lost']:4d}"
            f" {r['image_hz']:8.0f} {r['delivered_hz']:9.0f} {r['cpu_util']:10.0%} |"
            f" {fmt(r['idle_p50'], 15)}"
            f" {fmt(r['idle_p99'], 6)}"
        )
    print(
        "  where the time goes (ms): publish() called -> in the outbox -> the client starts"
        " writing it -> written -> server receipt stamp"
    )
    print(
        f"  {'':<29}{'-> outbox':^13} {'-> writing':^13} {'written -> receipt':^18}"
        f" {'publish()':>9} {'loop lag':>8} {'server':>7} {'GC':>6}"
    )
    print(
        f"  {'load':<15} {'priority':<8} {'conn':<4} {'p50':>6} {'p99':>6} {'p50':>6} {'p99':>6}"
        f" {'p50':>8} {'p99':>9} {'p99':>9} {'p99':>8} {'wake p99':>7} {'max':>6}  written by"
    )
    for r in rows:
        sent_by = ", ".join(
            f"{name.removeprefix('rmb-')} {n}" for name, n in sorted(r["sent_by"].items())
        )
        print(
            f"  {r['load']:<15} {r['priority']:<8} {r['connection']:<4}"
            f" {fmt(r['enqueue_p50'], 6)} {fmt(r['enqueue_p99'], 6)}"
            f" {fmt(r['outbox_p50'], 6)} {fmt(r['outbox_p99'], 6)}"
            f" {fmt(r['wire_p50'], 8)} {fmt(r['wire_p99'], 9)}"
            f" {fmt(r['call_p99'], 9)} {fmt(r['lag_p99'], 8)} {fmt(r['server_late_p99'], 7)}"
            f" {fmt(r['gc_max'], 6)}  {sent_by}"
        )
    for r in rows:
        if r["adaptive_drops"] or r["breaker_drops"] or r["overflow"]:
            print(
                f"  load {r['load']}, {r['priority']}, {r['connection']}: the image subscription"
                f" dropped {r['adaptive_drops']} frames in its adaptive throttle,"
                f" {r['breaker_drops']} in its circuit breaker, {r['overflow']} on overflow"
            )
    for r in rows:
        if r["priority"] == "control" and r["load"] != "none":
            verdict = "met" if r["p99"] < TARGET_P99_MS else "MISSED"
            how = "" if r["connection"] == "same" else ", control on its own connection"
            print(
                f"  target: control p99 < {TARGET_P99_MS:g} ms, load {r['load']}{how}:"
                f" {r['p99']:.2f} ms end to end -> {verdict}; in the client (publish() called"
                f" -> socket write) {r['queued_p99']:.2f} ms"
            )
    return rows


def report_throttle(backend: Backend, samples: list[ThrottleSample]) -> list[dict[str, Any]]:
    reps = max(Counter((s.load, s.client) for s in samples).values(), default=0)
    by: dict[tuple[str, str], list[ThrottleSample]] = {}
    for s in samples:
        by.setdefault((s.load, s.client), []).append(s)
    rows: list[dict[str, Any]] = []
    for (load, client), group in by.items():
        per = [s.cpu_per_1000 * 1e3 for s in group]  # ms per 1000 frames
        rows.append(
            {
                "load": load,
                "client": client,
                "frames_per_s": statistics.median(s.frames / s.seconds for s in group),
                "delivered_per_s": statistics.median(s.delivered / s.seconds for s in group),
                "cpu_ms_per_s": statistics.median(s.cpu / s.seconds * 1e3 for s in group),
                "cpu_ms_per_1000": statistics.median(per) if group[0].frames else float("nan"),
                "cpu_ms_per_1000_min": min(per),
                "cpu_ms_per_1000_max": max(per),
                "faults_per_frame": statistics.median(s.faults / max(s.frames, 1) for s in group),
            }
        )
    for row in rows:  # the same without the fixed cost of a connected, idle client
        idle = next(
            (
                r["cpu_ms_per_s"]
                for r in rows
                if r["load"] == row["load"] and r["client"] == IDLE_CLIENT
            ),
            0.0,
        )
        frames = row["frames_per_s"]
        row["cpu_ms_per_1000_net"] = (
            (row["cpu_ms_per_s"] - idle) / frames * 1e3
            if frames and row["client"] != "transport"
            else row["cpu_ms_per_1000"]
        )
    print(
        f"\n{backend}: throttling cost, client CPU per 1000 image frames received"
        f" (medians of {reps} windows)"
    )
    print(
        f"  {'load':<15} {'client':<31} {'frames/s':>8} {'delivered/s':>11} {'CPU ms/s':>8}"
        f" {'CPU ms/1000':>11} {'(min)':>7} {'(max)':>7} {'net of idle':>11} {'faults/frame':>12}"
    )
    for r in rows:
        delivered = "-" if r["client"] == "transport" else f"{r['delivered_per_s']:.1f}"
        print(
            f"  {r['load']:<15} {r['client']:<31} {r['frames_per_s']:8.0f} {delivered:>11}"
            f" {r['cpu_ms_per_s']:8.1f} {fmt(r['cpu_ms_per_1000'], 11)}"
            f" {fmt(r['cpu_ms_per_1000_min'], 7)} {fmt(r['cpu_ms_per_1000_max'], 7)}"
            f" {fmt(r['cpu_ms_per_1000_net'], 11)} {r['faults_per_frame']:12.1f}"
        )
    capped = f"library max_hz={THROTTLE_HZ:g}"
    for load in dict.fromkeys(r["load"] for r in rows):
        get = {r["client"]: r for r in rows if r["load"] == load}
        if capped not in get or "library" not in get:
            continue
        ratio = get[capped]["cpu_ms_per_1000"] / get["library"]["cpu_ms_per_1000"]
        net = get[capped]["cpu_ms_per_1000_net"] / get["library"]["cpu_ms_per_1000_net"]
        floor = get["transport"]["cpu_ms_per_1000"] / get["library"]["cpu_ms_per_1000"]
        verdict = "met" if ratio < TARGET_THROTTLE else "MISSED"
        print(
            f"  target: max_hz={THROTTLE_HZ:g} costs < {TARGET_THROTTLE:.0%} of unthrottled, load"
            f" {load}: {ratio:.0%} per frame -> {verdict}  (net of the idle client's cost:"
            f" {net:.0%}; the raw transport alone: {floor:.0%})"
        )
        per_s = get[capped]["cpu_ms_per_s"] / get["library"]["cpu_ms_per_s"]
        line = (
            f"    CPU per second on this stream: max_hz={THROTTLE_HZ:g} {per_s:.0%} of unthrottled"
        )
        if BANDWIDTH_CLIENT in get:
            saved = get[BANDWIDTH_CLIENT]["cpu_ms_per_s"] / get["library"]["cpu_ms_per_s"]
            line += f"; with save_bandwidth=True {saved:.0%}"
        print(line)
    return rows


def report_trace(backend: Backend, traced: Traced, tail: float = 0.05) -> dict[str, Any]:
    """Split the slowest ``tail`` of the traced control publishes into the
    client's wait (publish stamp to the start of the socket write) and the
    rest (write to the server's receipt), and attribute the client's wait to
    the task steps that ran in it."""
    sample, steps = traced.sample, traced.steps
    done = [r for r in sample.records if r.receipt_ns and r.write_start_ns]
    done.sort(key=lambda r: r.receipt_ns - r.publish_ns, reverse=True)
    slow = done[: max(1, round(len(done) * tail))]
    print(
        f"\n{backend}: --trace, control under full load, every task step timed"
        f" ({len(steps):,} steps; the instrumentation itself slows the loop)"
    )
    print(
        f"  latency p50 {pct(sample.latency_ms, 0.5):.2f} ms, p99 {pct(sample.latency_ms, 0.99):.2f}"
        f" ms; images/s {sample.image_hz:.0f}"
    )
    if not slow:
        return {}
    n = len(slow)
    enqueue = sum(r.queued_ns - r.publish_ns for r in slow if r.queued_ns) / n / 1e6
    client = sum(r.write_start_ns - r.publish_ns for r in slow) / n / 1e6
    write = sum(r.write_end_ns - r.write_start_ns for r in slow) / n / 1e6
    server = sum(r.receipt_ns - r.write_end_ns for r in slow) / n / 1e6
    writers = Counter(r.task.removeprefix("rmb-") for r in slow)
    print(
        f"  the slowest {n} ({tail:.0%}): mean latency {client + write + server:.2f} ms ="
        f" {client:.2f} in the client before the write ({enqueue:.2f} of it before"
        f" publish() put the frame in the outbox) + {write:.2f} writing + {server:.2f} from"
        f" the write to the server's receipt stamp; written by"
        f" {', '.join(f'{k} {v}' for k, v in writers.most_common())}"
    )
    windows = [(r.publish_ns, r.write_start_ns) for r in slow]
    shares, length = attribute(steps, windows)
    ranked = sorted(shares.items(), key=lambda kv: kv[1].wall, reverse=True)
    busy = sum(share.wall for share in shares.values())
    if length > 0:
        print("  while they waited in the client, the event loop ran (wall share, of it on CPU):")
        for name, share in ranked[:6]:
            print(
                f"    {share.wall / length:6.1%} ({share.cpu / max(share.wall, 1):4.0%} CPU)"
                f"  {name:<36} longest step {share.longest / 1e6:5.2f} ms"
                f" ({share.longest_cpu / 1e6:.2f} ms CPU)"
            )
        print(
            f"    {(length - busy) / length:6.1%}        (no task step: polling, or not scheduled)"
        )
    unread_share = float("nan")
    longest_unread = 0.0
    if traced.unread:
        intervals = unread_intervals(traced.unread)
        after = sum(r.receipt_ns - r.write_end_ns for r in slow)
        held = sum(overlap(intervals, r.write_end_ns, r.receipt_ns) for r in slow)
        unread_share = held / after if after > 0 else float("nan")
        longest_unread = max((e - s for s, e in intervals), default=0) / 1e6
        print(
            f"  between their write and the receipt stamp, the server's socket held unread"
            f" bytes {unread_share:.0%} of the time (/proc/net/tcp rx_queue; the longest"
            f" unread stretch in the case: {longest_unread:.1f} ms)"
        )
    return {
        "latency_p50": pct(sample.latency_ms, 0.5),
        "latency_p99": pct(sample.latency_ms, 0.99),
        "tail": n,
        "tail_client_wait_ms": client,
        "tail_before_outbox_ms": enqueue,
        "tail_write_ms": write,
        "tail_write_to_receipt_ms": server,
        "tail_unread_share": unread_share,
        "longest_unread_ms": longest_unread,
        "tasks": {name: asdict(share) for name, share in ranked},
        "window_ns": length,
        "sample": asdict(sample),
    }


def report_profiles(backend: Backend, profiles: dict[str, Profile]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for client, p in profiles.items():
        n = sum(p.own.values()) or 1
        print(
            f"\n{backend}: --profile, {client} on the full-rate stream:"
            f" {p.sample.frames:,} frames, {p.sample.cpu_per_1000 * 1e3:.0f} ms CPU per 1000,"
            f" {n:,} CPU samples"
        )
        print("  own time (the function itself):")
        for where, k in p.own.most_common(10):
            print(f"    {k / n:6.1%}  {where}")
        print("  inclusive, the library and websockets:")
        shown = [
            (w, k)
            for w, k in p.inclusive.most_common(60)
            if w.startswith(("ros_mobile_bridge/", "websockets/"))
        ]
        for where, k in shown[:10]:
            print(f"    {k / n:6.1%}  {where}")
        out[client] = {
            "samples": n,
            "own": {w: k / n for w, k in p.own.most_common(30)},
            "inclusive": {w: k / n for w, k in p.inclusive.most_common(60)},
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backend", choices=["asyncio", "trio", "both"], default="both")
    parser.add_argument(
        "--publishes", type=int, default=500, help="publishes per latency case (about 20 ms apart)"
    )
    parser.add_argument(
        "--seconds", type=float, default=3.0, help="length of one throttling window"
    )
    parser.add_argument("--reps", type=int, default=3, help="throttling windows per client")
    parser.add_argument(
        "--full-hz", type=float, default=2000.0, help="the server's pace for the full-rate load"
    )
    parser.add_argument(
        "--only", choices=["latency", "throttle"], help="run one of the two measurements"
    )
    parser.add_argument(
        "--malloc",
        choices=["default", "steady"],
        default="default",
        help="steady: glibc keeps freed memory (no page faults on fresh image buffers)",
    )
    parser.add_argument("--json", type=Path, help="also write every sample and summary here")
    parser.add_argument(
        "--trace", action="store_true", help="also attribute the control tail to event-loop tasks"
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="also profile an unthrottled and a max_hz=5 window on the full-rate stream",
    )
    args = parser.parse_args()
    backends: list[Backend] = ["asyncio", "trio"] if args.backend == "both" else [args.backend]
    settings = Settings(
        args.publishes,
        args.seconds,
        args.reps,
        args.full_hz,
        latency=args.only in (None, "latency"),
        throttle=args.only in (None, "throttle"),
        trace=args.trace,
        profile=args.profile,
    )
    if args.malloc == "steady":
        steady_malloc()
    print(versions())
    print(
        f"{platform.machine()}, {len(os.sched_getaffinity(0))} CPUs, malloc {args.malloc};"
        f" server: foxglove-sdk in a subprocess, per-client backlog {BACKLOG};"
        f" image 640x480 rgb8 (921,652 B CDR); full rate = the server paced at"
        f" {args.full_hz:g}/s; {args.publishes} publishes per latency case,"
        f" {SPACING[0] * 1e3:g}-{SPACING[1] * 1e3:g} ms apart"
    )
    out: dict[str, Any] = {"versions": versions(), "args": {**vars(args), "json": str(args.json)}}
    peer = Peer()
    seq = 1
    try:
        for backend in backends:
            result = anyio.run(run_backend, peer, backend, settings, seq, backend=backend)
            seq += args.publishes * 10
            entry: dict[str, Any] = {}
            if result.latency:
                entry["latency"] = report_latency(backend, result.latency)
                entry["latency_samples"] = [asdict(s) for s in result.latency]
            if result.throttle:
                entry["throttle"] = report_throttle(backend, result.throttle)
                entry["throttle_samples"] = [asdict(s) for s in result.throttle]
            if result.trace is not None:
                entry["trace"] = report_trace(backend, result.trace)
            if result.profiles:
                entry["profile"] = report_profiles(backend, result.profiles)
            out[backend] = entry
    finally:
        peer.close()
    if args.json:
        args.json.write_text(json.dumps(out, indent=2, default=str))
        print(f"\nwrote {args.json}")


if __name__ == "__main__":
    main()
