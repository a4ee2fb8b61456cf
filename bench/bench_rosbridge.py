"""rosbridge receive benchmark: this library against roslibpy on one real bridge (stand-alone script).

    .venv/bin/python bench/bench_rosbridge.py [--only small|images] [--seconds 5]
        [--repeats 3] [--warmup 1.5] [--json PATH] [--profile]

Needs ``pip install roslibpy`` (not a project dependency; the script says so
and exits if it is missing) and, for ``--profile``, ``py-spy``.

One run starts its own ROS 2 graph and Rust rosbridge server (the test peers:
``tests/peers``, a ROS 2 Jazzy environment with ``rosbridge_server_rs``, built
once and cached) on 127.0.0.1, then measures every client on the same bridge
and the same topics, one client at a time, each in its own subprocess (this
script with ``--client``), so the CPU time of a client is that process's alone.

Cases:

* ``String 1 kHz`` and ``String 5 kHz``: ``std_msgs/msg/String``, 64
  characters, from ``bench/_ros_publisher.py`` (an rclpy node in the peer
  environment publishing on a fixed schedule; the first 10 characters are the
  sequence number). The graph node's rclpy timer reaches neither rate.
* ``Image 30 Hz``: ``sensor_msgs/msg/Image`` 640x480 rgb8 (921,600 bytes of
  pixels) from the graph node's ``image`` command; ``header.frame_id`` is the
  sequence number.

Clients (the consumer work per message is the same function for all of them,
see :func:`make_take`): the library on asyncio and on trio, with JSON and, for
images, ``compression="cbor"`` and ``"cbor-raw"``; for Strings also the
library on asyncio with ``read_coalesce=0`` (every frame read and handed over
as it arrives, as before issue 10) and on asyncio with uvloop's loop;
roslibpy (its default twisted transport; it has no CBOR: it refuses any
``compression`` but ``png`` and ``none``, and raises on binary frames); a raw
``websockets`` asyncio loop that sends the ``subscribe`` op and
``json.loads`` every frame (the floor; for Strings on uvloop too, the
library on uvloop's baseline), and the same loop on this library's own
WebSocket (``transport.connect_websocket``).

In each client process, after the first message and a warm-up, a window of
``--seconds`` is measured: messages received, ``getrusage(RUSAGE_SELF)`` (user
and system CPU time of every thread of the process, voluntary context
switches), the sequence numbers of the last
message before and at the end of the window (so messages lost in the window
are counted exactly), and the publisher's own count at both ends (so the
actual published rate is known). For Strings, each message's delay from
the publisher's ``publish`` call to the consumer (p50, p99, max of the
window; the publisher writes its send time into the text) shows what read
coalescing adds. Repetitions rotate the order of the
clients; the table shows medians. ``--profile`` adds one window per library
client with ``py-spy record --nonblocking`` attached for its duration. See
``bench/README.md``.
"""

from __future__ import annotations

import argparse
import base64
import collections
import importlib.metadata
import json
import os
import platform
import queue
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from contextlib import suppress
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Any, Final

HERE: Final = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.insert(0, str(HERE))
from _common import DROP_REASONS, check_fates, run_on, subscription_counts  # noqa: E402
from _common import versions as common_versions  # noqa: E402

STRING_TYPE: Final = "std_msgs/msg/String"
IMAGE_TYPE: Final = "sensor_msgs/msg/Image"
STRING_CHARS: Final = 64
IMAGE_TOPIC: Final = "/bench/image"
IMAGE_HZ: Final = 30.0
PUBLISHER: Final = HERE / "_ros_publisher.py"
CHILD_SLACK: Final = 30.0
"""Seconds a client process may take beyond warm-up and window (connecting)."""
TARGET: Final = 0.5
"""The issue's target: at most this fraction of roslibpy's CPU per message."""


# -- the client processes -------------------------------------------------------------


class Got:
    """What a client received. ``last`` is ``(count, sequence text)`` of the
    newest message, one object, so another thread reads a consistent pair."""

    __slots__ = ("bytes", "delays", "last", "n")

    def __init__(self) -> None:
        self.n = 0
        self.bytes = 0
        self.last: tuple[int, str] | None = None
        self.delays: list[int] = []  # ns from publish to the consumer, Strings only


def make_take(got: Got, kind: str) -> Callable[[dict[str, Any]], None]:
    """The consumer work per message, the same for every client.

    String: keep a reference to ``data`` (the string). Image: get the pixels
    as a real consumer needs them, ``base64.b64decode`` of the JSON ``data``
    field; keep ``header.frame_id``. A
    String's delay from its publish to here is noted too (the publisher
    wrote its send time into the text). The raw clients' messages are
    dicts; the library's are instances: see :func:`make_take_instance`."""
    if kind == "string":
        delays = got.delays
        now_ns = time.monotonic_ns

        def take(data: dict[str, Any]) -> None:
            n = got.n + 1
            got.n = n
            text = data["data"]
            got.last = (n, text)
            delays.append(now_ns() - int(text[11:30]))

    else:

        def take(data: dict[str, Any]) -> None:
            got.bytes += len(base64.b64decode(data["data"]))
            n = got.n + 1
            got.n = n
            got.last = (n, data["header"]["frame_id"])

    return take


def make_take_instance(got: Got, kind: str) -> Callable[[Any], None]:
    """:func:`make_take` for the library's messages, instances of the
    message's class: the same work, by attribute (an image's pixels are
    already a numpy array, decoded from base64 or CBOR by the library)."""
    if kind == "string":
        delays = got.delays
        now_ns = time.monotonic_ns

        def take(data: Any) -> None:
            n = got.n + 1
            got.n = n
            text = data.data
            got.last = (n, text)
            delays.append(now_ns() - int(text[11:30]))

    else:

        def take(data: Any) -> None:
            got.bytes += len(data.data)
            n = got.n + 1
            got.n = n
            got.last = (n, data.header.frame_id)

    return take


def seq_of(kind: str, text: str) -> int:
    return int(text[:10]) if kind == "string" else int(text)


@dataclass
class Snap:
    wall: float
    user: float
    sys: float
    switches: int
    n: int
    seq: int
    delays: int
    extra: dict[str, int]


def snap(got: Got, kind: str, extra: Callable[[], dict[str, int]] | None = None) -> Snap:
    """Now: wall clock, this process's user and system CPU time (every
    thread) and voluntary context switches (sleeps: one per wake-up of an
    idle event loop), the newest message."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    wall = time.perf_counter()
    last = got.last
    assert last is not None
    return Snap(
        wall,
        usage.ru_utime,
        usage.ru_stime,
        usage.ru_nvcsw,
        last[0],
        seq_of(kind, last[1]),
        len(got.delays),
        extra() if extra else {},
    )


def say(line: str) -> None:
    sys.stdout.write(line + "\n")
    sys.stdout.flush()


def delay_ms(delays: list[int], q: float) -> float | None:
    """The ``q`` quantile of ``delays`` (ns) in ms; None without any."""
    if not delays:
        return None
    ordered = sorted(delays)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] / 1e6


def report_window(a: Snap, b: Snap, got: Got) -> None:
    say("end")
    window = got.delays[a.delays : b.delays]
    result = {
        "messages": b.n - a.n,
        "seconds": b.wall - a.wall,
        "cpu_user": b.user - a.user,
        "cpu_sys": b.sys - a.sys,
        "switches": b.switches - a.switches,
        "seq_first": a.seq,
        "seq_last": b.seq,
        "bytes": got.bytes,
        "delay_p50_ms": delay_ms(window, 0.5),
        "delay_p99_ms": delay_ms(window, 0.99),
        "delay_max_ms": delay_ms(window, 1.0),
        "extra": {k: b.extra[k] - a.extra.get(k, 0) for k in b.extra},
    }
    say("result " + json.dumps(result))


def child_library(
    args: argparse.Namespace, backend: str, compression: str | None, read_coalesce: float | None
) -> None:
    """The library with default options (``read_coalesce`` overrides that
    option when given)."""
    import anyio

    import ros_mobile_bridge as rmb

    async def main() -> None:
        got = Got()
        take = make_take_instance(got, args.kind)
        options = rmb.ClientOptions(reconnect=None, latency_probe_interval=0)
        if read_coalesce is not None:
            options = replace(options, read_coalesce=read_coalesce)
        async with (
            rmb.connect(args.url, protocol="rosbridge", options=options) as robot,
            robot.subscribe(
                args.topic, compression=compression, buffer=100_000, adaptive=False
            ) as sub,
        ):
            first = anyio.Event()

            async def consume() -> None:
                async for msg in sub:
                    take(msg.data)
                    if got.n == 1:
                        first.set()

            def extra() -> dict[str, int]:
                return subscription_counts(sub)

            async with anyio.create_task_group() as tg:
                tg.start_soon(consume)
                await first.wait()
                await anyio.sleep(args.warmup)
                a = snap(got, args.kind, extra)
                say("start")
                await anyio.sleep(args.seconds)
                b = snap(got, args.kind, extra)
                report_window(a, b, got)
                tg.cancel_scope.cancel()

    run_on(backend, main)


def child_raw(args: argparse.Namespace, *, uvloop: bool = False) -> None:
    import asyncio

    from websockets.asyncio.client import connect

    async def main() -> None:
        got = Got()
        take = make_take(got, args.kind)
        typename = STRING_TYPE if args.kind == "string" else IMAGE_TYPE
        async with connect(
            args.url, compression=None, max_size=None, ping_interval=None, proxy=None
        ) as ws:
            op = {"op": "subscribe", "id": "raw", "topic": args.topic, "type": typename}
            await ws.send(json.dumps(op))
            first = asyncio.Event()

            async def consume() -> None:
                loads = json.loads
                async for frame in ws:
                    message = loads(frame)
                    if message.get("op") == "publish":
                        take(message["msg"])
                        if got.n == 1:
                            first.set()

            task = asyncio.create_task(consume())
            await first.wait()
            await asyncio.sleep(args.warmup)
            a = snap(got, args.kind)
            say("start")
            await asyncio.sleep(args.seconds)
            b = snap(got, args.kind)
            report_window(a, b, got)
            task.cancel()
            with suppress(asyncio.CancelledError):
                await task

    if uvloop:  # asyncio on uvloop's loop
        import uvloop as uv

        uv.run(main())
    else:
        asyncio.run(main())


def child_transport(args: argparse.Namespace) -> None:
    """This library's WebSocket alone (``transport.connect_websocket``, anyio
    on asyncio) in the same raw loop as :func:`child_raw`."""
    import anyio

    from ros_mobile_bridge.transport import connect_websocket

    async def main() -> None:
        got = Got()
        take = make_take(got, args.kind)
        typename = STRING_TYPE if args.kind == "string" else IMAGE_TYPE
        ws = await connect_websocket(args.url, max_size=None)
        try:
            op = {"op": "subscribe", "id": "raw", "topic": args.topic, "type": typename}
            await ws.send(json.dumps(op))
            first = anyio.Event()

            async def consume() -> None:
                loads = json.loads
                receive = ws.receive
                while True:
                    message = loads(await receive())
                    if message.get("op") == "publish":
                        take(message["msg"])
                        if got.n == 1:
                            first.set()

            async with anyio.create_task_group() as tg:
                tg.start_soon(consume)
                await first.wait()
                await anyio.sleep(args.warmup)
                a = snap(got, args.kind)
                say("start")
                await anyio.sleep(args.seconds)
                b = snap(got, args.kind)
                report_window(a, b, got)
                tg.cancel_scope.cancel()
        finally:
            await ws.aclose()

    anyio.run(main, backend="asyncio")


def child_roslibpy(args: argparse.Namespace) -> None:
    import roslibpy

    host, port = args.url.removeprefix("ws://").rsplit(":", 1)
    got = Got()
    take = make_take(got, args.kind)
    ros = roslibpy.Ros(host=host, port=int(port))
    ros.run()
    typename = STRING_TYPE if args.kind == "string" else IMAGE_TYPE
    topic = roslibpy.Topic(ros, args.topic, typename)
    topic.subscribe(take)
    deadline = time.monotonic() + CHILD_SLACK
    while got.last is None:
        if time.monotonic() > deadline:
            raise SystemExit("roslibpy: no message")
        time.sleep(0.02)
    time.sleep(args.warmup)
    a = snap(got, args.kind)
    say("start")
    time.sleep(args.seconds)
    b = snap(got, args.kind)
    report_window(a, b, got)
    with suppress(Exception):
        topic.unsubscribe()
        ros.close(timeout=2)  # a WebSocket close, not a reset
        time.sleep(0.3)  # close() returns when the close frame is queued, not sent
    os._exit(0)  # the twisted reactor cannot be restarted or joined cleanly


def child_main(args: argparse.Namespace) -> None:
    name = args.client
    if name == "roslibpy":
        child_roslibpy(args)
    elif name in ("websockets raw", "websockets raw uvloop"):
        child_raw(args, uvloop=name.endswith("uvloop"))
    elif name == "rmb transport raw":
        child_transport(args)
    else:
        _, backend, *rest = name.split()
        uncoalesced = "uncoalesced" in rest
        rest = [word for word in rest if word != "uncoalesced"]
        compression = rest[0] if rest and rest[0] != "json" else None
        child_library(
            args, backend, compression, read_coalesce=0.0 if uncoalesced else args.read_coalesce
        )


# -- the parent: peers, publishers, runs ---------------------------------------------


@dataclass(frozen=True)
class Case:
    key: str
    label: str
    kind: str  # "string" | "image"
    topic: str
    rate: float
    clients: tuple[str, ...]


SMALL_CLIENTS: Final = (
    "library asyncio",
    "library trio",
    "library uvloop",
    "library asyncio uncoalesced",
    "roslibpy",
    "websockets raw",
    "websockets raw uvloop",
    "rmb transport raw",
)
IMAGE_CLIENTS: Final = (
    "library asyncio json",
    "library asyncio cbor",
    "library asyncio cbor-raw",
    "library trio json",
    "library trio cbor",
    "library trio cbor-raw",
    "roslibpy",
    "websockets raw",
    "rmb transport raw",
)


def all_cases(only: str | None) -> list[Case]:
    cases = []
    if only in (None, "small"):
        for hz in (1000, 5000):
            cases.append(
                Case(
                    f"string_{hz // 1000}khz",
                    f"String {hz // 1000} kHz ({STRING_CHARS} chars)",
                    "string",
                    f"/bench/string_{hz // 1000}khz",
                    float(hz),
                    SMALL_CLIENTS,
                )
            )
    if only in (None, "images"):
        cases.append(
            Case(
                "image_30hz",
                "Image 30 Hz 640x480 rgb8",
                "image",
                IMAGE_TOPIC,
                IMAGE_HZ,
                IMAGE_CLIENTS,
            )
        )
    return cases


class StringPublisher:
    """``_ros_publisher.py`` in the peer environment, stopped by its pid."""

    def __init__(self, env: Any, domain_id: int, topic: str, rate: float) -> None:
        self.proc = subprocess.Popen(
            [str(env.python), str(PUBLISHER), topic, str(rate), str(STRING_CHARS)],
            env=env.node_env(domain_id),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        assert self.proc.stdin is not None
        assert self.proc.stdout is not None
        self._in, self._out = self.proc.stdin, self.proc.stdout
        if self._out.readline().strip() != "ready":
            self.stop()
            raise RuntimeError("the String publisher did not start")

    def count(self) -> tuple[int, float]:
        self._in.write("count\n")
        self._in.flush()
        words = self._out.readline().split()
        if len(words) != 3 or words[0] != "count":
            raise RuntimeError(f"the String publisher answered {words!r}")
        return int(words[1]), time.monotonic()

    def stop(self) -> None:
        if self.proc.poll() is None:
            with suppress(OSError):
                self._in.write("quit\n")
                self._in.close()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()


@dataclass
class Sample:
    """One client's window."""

    messages: int
    seconds: float
    cpu_user: float
    cpu_sys: float
    switches: int
    seq_first: int
    seq_last: int
    published: int
    published_seconds: float
    behind: int
    delay_p50_ms: float | None = None
    delay_p99_ms: float | None = None
    delay_max_ms: float | None = None
    extra: dict[str, int] = field(default_factory=dict)
    profile: dict[str, Any] | None = None

    @property
    def rate(self) -> float:
        return self.messages / self.seconds

    @property
    def published_rate(self) -> float:
        return self.published / self.published_seconds

    @property
    def cpu(self) -> float:
        return self.cpu_user + self.cpu_sys

    @property
    def cpu_us(self) -> float:
        return self.cpu / self.messages * 1e6 if self.messages else float("nan")

    @property
    def gaps(self) -> int:
        """Sequence numbers in the window that this client never received."""
        return self.seq_last - self.seq_first - self.messages


def run_client(
    name: str,
    case: Case,
    url: str,
    count: Callable[[], tuple[int, float]],
    seconds: float,
    warmup: float,
    profile: bool = False,
    extra: tuple[str, ...] = (),
) -> Sample:
    """One client process: start it, note the publisher's count when its
    window starts and ends, read its result, wait for it to exit."""
    argv = [
        sys.executable,
        str(Path(__file__).resolve()),
        "--client",
        name,
        "--url",
        url,
        "--topic",
        case.topic,
        "--kind",
        case.kind,
        "--seconds",
        str(seconds),
        "--warmup",
        str(warmup),
        *extra,
    ]
    spy: subprocess.Popen[bytes] | None = None
    spy_out = Path(tempfile.mkstemp(prefix="rmb-bench-pyspy-", suffix=".txt")[1])
    with tempfile.TemporaryFile() as errors:
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=errors, text=True)
        lines: queue.Queue[str | None] = queue.Queue()

        def read() -> None:
            assert proc.stdout is not None
            for line in proc.stdout:
                lines.put(line.strip())
            lines.put(None)

        threading.Thread(target=read, daemon=True).start()
        deadline = time.monotonic() + warmup + seconds + CHILD_SLACK
        marks: dict[str, tuple[int, float]] = {}
        result: dict[str, Any] | None = None
        try:
            while result is None:
                try:
                    line = lines.get(timeout=max(0.1, deadline - time.monotonic()))
                except queue.Empty:
                    raise RuntimeError(f"{name}: no result in time") from None
                if line is None:
                    break
                if line in ("start", "end"):
                    marks[line] = count()
                    if line == "start" and profile:
                        spy = start_py_spy(proc.pid, seconds, spy_out)
                elif line.startswith("result "):
                    result = json.loads(line.removeprefix("result "))
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            if spy is not None:
                try:
                    spy.wait(timeout=15)
                except subprocess.TimeoutExpired:
                    spy.kill()
                    spy.wait()
        stacks = read_collapsed(spy_out) if spy is not None else None
        spy_out.unlink(missing_ok=True)
        if result is None or set(marks) != {"start", "end"}:
            errors.seek(0)
            tail = errors.read().decode(errors="replace")[-3000:]
            raise RuntimeError(f"{name} on {case.label} failed (exit {proc.returncode}):\n{tail}")
    (c0, t0), (c1, t1) = marks["start"], marks["end"]
    return Sample(
        messages=result["messages"],
        seconds=result["seconds"],
        cpu_user=result["cpu_user"],
        cpu_sys=result["cpu_sys"],
        switches=result["switches"],
        seq_first=result["seq_first"],
        seq_last=result["seq_last"],
        published=c1 - c0,
        published_seconds=t1 - t0,
        behind=c1 - 1 - result["seq_last"],
        delay_p50_ms=result.get("delay_p50_ms"),
        delay_p99_ms=result.get("delay_p99_ms"),
        delay_max_ms=result.get("delay_max_ms"),
        extra=result["extra"],
        profile=stacks,
    )


def start_py_spy(pid: int, seconds: float, out: Path) -> subprocess.Popen[bytes]:
    """py-spy sampling ``pid`` (not pausing it) for ``seconds``, writing
    collapsed stacks (``frame;frame;... count``, active samples only)."""
    exe = shutil.which("py-spy") or str(Path(sys.executable).with_name("py-spy"))
    return subprocess.Popen(
        [
            exe,
            "record",
            "--pid",
            str(pid),
            "--duration",
            str(max(1, round(seconds))),
            "--rate",
            "1000",
            "--nonblocking",
            "--format",
            "raw",
            "--output",
            str(out),
        ],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )


def read_collapsed(path: Path) -> dict[str, Any] | None:
    """Own and inclusive shares per function from py-spy's collapsed stacks."""
    own: collections.Counter[str] = collections.Counter()
    total: collections.Counter[str] = collections.Counter()
    layers: collections.Counter[str] = collections.Counter()
    samples = 0
    with suppress(OSError):
        for line in path.read_text().splitlines():
            stack, _, n = line.rpartition(" ")
            if not stack or not n.isdigit():
                continue
            count = int(n)
            frames = [short_frame(f) for f in stack.split(";")]
            frames = [f for f in frames if f]
            if not frames:
                continue
            samples += count
            own[frames[-1]] += count
            layers[layer(frames[-1])] += count
            for f in set(frames):
                total[f] += count
    if not samples:
        return None
    return {
        "samples": samples,
        "layers": [(f, c / samples) for f, c in layers.most_common()],
        "own": [(f, c / samples) for f, c in own.most_common(25)],
        "inclusive": [(f, c / samples) for f, c in total.most_common(80)],
    }


LAYERS: Final = (
    ("event loop", ("asyncio/", "selectors.py", "anyio/", "trio/", "outcome/", "sniffio/")),
    ("websockets", ("websockets/",)),
    ("ros_mobile_bridge", ("ros_mobile_bridge/",)),
    ("json / cbor / base64", ("json/", "cbor2/", "base64.py")),
    ("the consumer (bench)", ("bench_rosbridge.py",)),
)


def layer(frame: str) -> str:
    """Which layer a function (as :func:`short_frame` names it) belongs to."""
    for name, prefixes in LAYERS:
        if frame.startswith(prefixes):
            return name
    return "other (dataclass __init__s, typing, ...)"


def short_frame(frame: str) -> str:
    """``func (path/to/file.py:123)`` -> ``file path after site-packages/ or
    src/: func`` (the line number dropped, so one function is one entry)."""
    name, _, where = frame.partition(" (")
    path = where.rstrip(")").rsplit(":", 1)[0]
    for marker in ("site-packages/", "/src/", "/lib/python3.11/"):
        if marker in path:
            path = path.split(marker, 1)[1]
            break
    return f"{path}:{name}"


def wait_topic(bridge: Any, topic: str, typename: str, timeout: float = 30.0) -> None:
    """Poll ``/rosapi/topics`` through the bridge until it lists ``topic``
    with ``typename`` (discovery of a new publisher takes 1.5 to 2.5 s)."""
    deadline = time.monotonic() + timeout
    while True:
        values = bridge.call_service("/rosapi/topics")["values"]
        if dict(zip(values["topics"], values["types"], strict=True)).get(topic) == typename:
            return
        if time.monotonic() > deadline:
            raise RuntimeError(f"the bridge did not discover {topic} within {timeout} s")
        time.sleep(0.25)


def run_case(
    case: Case,
    env: Any,
    graph: Any,
    bridge: Any,
    seconds: float,
    repeats: int,
    warmup: float,
    profile: bool,
    extra: tuple[str, ...] = (),
) -> tuple[dict[str, list[Sample]], dict[str, Sample]]:
    publisher: StringPublisher | None = None
    if case.kind == "string":
        publisher = StringPublisher(env, graph.domain_id, case.topic, case.rate)
        count = publisher.count
        typename = STRING_TYPE
    else:
        graph.command({"cmd": "image", "topic": case.topic, "hz": case.rate})

        def count() -> tuple[int, float]:
            return int(graph.command({"cmd": "count", "topic": case.topic})), time.monotonic()

        typename = IMAGE_TYPE
    samples: dict[str, list[Sample]] = {name: [] for name in case.clients}
    profiled: dict[str, Sample] = {}
    try:
        wait_topic(bridge, case.topic, typename)
        names = list(case.clients)
        for rep in range(repeats):
            order = names[rep % len(names) :] + names[: rep % len(names)]
            for name in order:
                sample = run_client(name, case, bridge.url, count, seconds, warmup, extra=extra)
                samples[name].append(sample)
            print(
                f"  {case.label}: repetition {rep + 1}/{repeats} done", file=sys.stderr, flush=True
            )
        if profile:
            for name in names:
                if name.startswith("library"):
                    profiled[name] = run_client(
                        name, case, bridge.url, count, seconds, warmup, profile=True, extra=extra
                    )
    finally:
        if publisher is not None:
            publisher.stop()
        else:
            with suppress(Exception):
                graph.command({"cmd": "stop", "topic": case.topic})
    return samples, profiled


# -- reporting -----------------------------------------------------------------------


def summarize(samples: list[Sample]) -> dict[str, float]:
    cpu = [s.cpu_us for s in samples]
    med = statistics.median(cpu)
    extra_keys = sorted({k for s in samples for k in s.extra})
    return {
        "received_per_s": statistics.median(s.rate for s in samples),
        "published_per_s": statistics.median(s.published_rate for s in samples),
        "cpu_us_per_msg": med,
        "cpu_us_per_msg_min": min(cpu),
        "cpu_spread": (max(cpu) - min(cpu)) / med if med else 0.0,
        "cpu_util": statistics.median(s.cpu / s.seconds for s in samples),
        "sys_share": statistics.median(s.cpu_sys / s.cpu for s in samples if s.cpu),
        "wakeups_per_msg": statistics.median(s.switches / max(s.messages, 1) for s in samples),
        "gaps_per_s": statistics.median(s.gaps / s.seconds for s in samples),
        "gaps_total": float(sum(s.gaps for s in samples)),
        "behind_max": float(max(s.behind for s in samples)),
        **{
            f"delay_{q}_ms": statistics.median(v)
            for q in ("p50", "p99", "max")
            if (v := [d for s in samples if (d := getattr(s, f"delay_{q}_ms")) is not None])
        },
        **{f"{k}_total": float(sum(s.extra.get(k, 0) for s in samples)) for k in extra_keys},
    }


def fate_problems(case: Case, samples: dict[str, list[Sample]]) -> list[str]:
    """Frames a library client received in a window and then lost: vanished
    (not delivered, not dropped for a counted reason, not queued) or dropped
    at all (no case here has a cap or a reason to drop)."""
    return [
        f"{case.label} / {name}, window {i + 1}: {problem}"
        for name, lst in samples.items()
        if name.startswith("library")
        for i, sample in enumerate(lst)
        if sample.extra
        for problem in check_fates(sample.extra)
    ]


def report(case: Case, samples: dict[str, list[Sample]]) -> dict[str, dict[str, float]]:
    table = {name: summarize(lst) for name, lst in samples.items()}
    n = len(next(iter(samples.values())))
    print(f"\n{case.label}: medians of {n} windows")
    header = (
        f"  {'client':<26} {'recv/s':>8} {'pub/s':>8} {'CPU us/msg':>11} {'(min)':>9}"
        f" {'spread':>6} {'CPU util':>8} {'sys':>4} {'sleeps/msg':>10} {'gaps/s':>7}"
        f" {'behind':>6} {'lib drops':>9} {'vs roslibpy':>11} {'delay p50/p99/max ms':>21}"
    )
    print(header)
    base = table["roslibpy"]["cpu_us_per_msg"]
    for name, s in table.items():
        drops = (
            f"{sum(s[f'{r}_total'] for r in DROP_REASONS):9.0f}"
            if "dropped_overflow_total" in s
            else f"{'-':>9}"
        )
        print(
            f"  {name:<26} {s['received_per_s']:8.1f} {s['published_per_s']:8.1f}"
            f" {s['cpu_us_per_msg']:11.1f} {s['cpu_us_per_msg_min']:9.1f}"
            f" {s['cpu_spread']:6.0%} {s['cpu_util']:8.1%} {s['sys_share']:4.0%}"
            f" {s['wakeups_per_msg']:10.2f} {s['gaps_per_s']:7.1f}"
            f" {s['behind_max']:6.0f} {drops} {s['cpu_us_per_msg'] / base:10.2f}x"
            + (
                f" {s['delay_p50_ms']:6.2f} /{s['delay_p99_ms']:6.2f} /{s['delay_max_ms']:6.1f}"
                if "delay_p50_ms" in s
                else ""
            )
        )
    libraries = [
        name
        for name in table
        if name.startswith("library") and (case.kind == "string" or not name.endswith("json"))
    ]
    for name in libraries:
        ratio = table[name]["cpu_us_per_msg"] / base
        verdict = "met" if ratio <= TARGET else "MISSED"
        print(f"  target (<= 0.5x roslibpy's CPU per message): {name}: {ratio:.2f}x -> {verdict}")
    pairs = (
        ("library uvloop", "websockets raw uvloop", "a raw websockets client on the same uvloop"),
        ("library uvloop", "library asyncio", "the library on plain asyncio"),
        ("websockets raw uvloop", "websockets raw", "raw websockets on plain asyncio"),
    )
    for a, b, what in pairs:
        if a in table and b in table:
            x, y = table[a]["cpu_us_per_msg"], table[b]["cpu_us_per_msg"]
            print(f"  {a} / {what}: {x / y:.2f}x CPU per message")
    return table


def report_profile(case: Case, profiled: dict[str, Sample]) -> None:
    """Print where each profiled library client's CPU went (shares of the
    samples of one window, taken after the measured ones)."""
    skip = ("asyncio/", "anyio/", "trio/", "selectors.py", "bench_rosbridge.py", "threading.py")
    for name, sample in profiled.items():
        prof = sample.profile
        if not prof:
            continue
        print(
            f"\nprofile: {name}, {case.label}: {prof['samples']} py-spy samples of the running"
            f" thread in one window ({sample.cpu_us:.1f} us CPU per message,"
            f" {sample.rate:.0f} msg/s, {sample.cpu_sys / sample.cpu:.0%} of it in the kernel)"
        )
        print("  own time by layer:")
        for where, share in prof["layers"]:
            print(f"    {share:6.1%}  {where}")
        print("  own time (the function itself):")
        for where, share in prof["own"][:18]:
            print(f"    {share:6.1%}  {where}")
        print("  inclusive (library and websockets functions and what they call):")
        shown = [(w, x) for w, x in prof["inclusive"] if not w.startswith(skip) and "<" not in w]
        for where, share in shown[:14]:
            print(f"    {share:6.1%}  {where}")


def versions() -> str:
    return common_versions(
        (
            "ros-mobile-bridge",
            "roslibpy",
            "twisted",
            "autobahn",
            "websockets",
            "anyio",
            "trio",
            "cbor2",
            "numpy",
        )
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", choices=["small", "images"], help="run only these cases")
    parser.add_argument("--seconds", type=float, default=5.0, help="measured window per client")
    parser.add_argument("--repeats", type=int, default=3, help="windows per client (medians)")
    parser.add_argument("--warmup", type=float, default=1.5, help="seconds after the first message")
    parser.add_argument("--json", type=Path, help="also write every sample and summary here")
    parser.add_argument(
        "--read-coalesce",
        type=float,
        help="ClientOptions.read_coalesce of the library clients (default: the option's default)",
    )
    parser.add_argument(
        "--profile",
        action="store_true",
        help="after the measured windows, one profiled window per library client",
    )
    # a client process (internal)
    parser.add_argument("--client", help=argparse.SUPPRESS)
    parser.add_argument("--url", help=argparse.SUPPRESS)
    parser.add_argument("--topic", help=argparse.SUPPRESS)
    parser.add_argument("--kind", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client:
        child_main(args)
        return

    try:
        importlib.metadata.version("roslibpy")
    except importlib.metadata.PackageNotFoundError:
        raise SystemExit(
            "bench_rosbridge.py compares against roslibpy, which is not installed here:"
            " run `.venv/bin/pip install roslibpy` first (see bench/README.md)"
        ) from None
    from peers.ros_env import RUNTIME_REQUIREMENTS, ensure_peer_env
    from peers.rosbridge import RosBridge, RosGraph

    bridge_version = next(r for r in RUNTIME_REQUIREMENTS if r.startswith("rosbridge-server-rs"))
    print(versions())
    print(
        f"{platform.machine()}, {len(os.sched_getaffinity(0))} CPUs; {bridge_version} and the"
        " ROS 2 graph in subprocesses on 127.0.0.1; every client in its own process"
    )
    print(f"window {args.seconds:g} s after {args.warmup:g} s of warm-up, {args.repeats} repeats")
    env = ensure_peer_env()
    out: dict[str, Any] = {"versions": versions(), "bridge": bridge_version, "args": {}}
    out["args"] = {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}
    graph = RosGraph.start(env)
    bridge = None
    problems: list[str] = []
    try:
        bridge = RosBridge.start(env, graph.domain_id)
        for case in all_cases(args.only):
            extra = (
                () if args.read_coalesce is None else ("--read-coalesce", str(args.read_coalesce))
            )
            samples, profiled = run_case(
                case,
                env,
                graph,
                bridge,
                args.seconds,
                args.repeats,
                args.warmup,
                args.profile,
                extra,
            )
            summary = report(case, samples)
            problems += fate_problems(case, samples)
            report_profile(case, profiled)
            out[case.key] = {
                "summary": summary,
                "profiles": {name: s.profile for name, s in profiled.items()},
                "samples": {
                    name: [{**asdict(s), "gaps": s.gaps, "profile": None} for s in lst]
                    for name, lst in samples.items()
                },
            }
    finally:
        if bridge is not None:
            bridge.stop()
        graph.stop()
    out["problems"] = problems
    if args.json:
        args.json.write_text(json.dumps(out, indent=2))
        print(f"\nwrote {args.json}")
    if problems:
        print("\nFAILED: the library lost frames it received:", file=sys.stderr)
        for problem in problems:
            print(f"  {problem}", file=sys.stderr)
        raise SystemExit(1)


if __name__ == "__main__":
    main()
