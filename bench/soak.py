"""A soak: one client of this library against a robot whose bridge crashes and returns.

    PYTHONPATH=src .venv/bin/python bench/soak.py --transport foxglove --loop asyncio \\
        --minutes 60 --kill-every 120 --json soak.json [--trace-memory]

The robot (``bench/_soak_robot.py``, its own processes) publishes a camera
(``sensor_msgs/msg/Image`` 640x480 rgb8, 30 Hz) and odometry
(``nav_msgs/msg/Odometry``, 50 Hz) and records every ``/cmd_vel`` Twist it
receives. The client (its own process: ``rmb.connect`` with a reconnect
policy, on ``--loop``) subscribes to both streams and publishes a Twist on
``/cmd_vel`` at 20 Hz with ``priority="control"``, its sequence number (from
1) in ``linear.y``, recording for each publish whether it returned or raised
and how long it took. Every ``--kill-every`` seconds (0: never) the peer the
client is connected to is killed with SIGKILL, as a crash, and started again
on the same port:

* ``foxglove``: the Foxglove SDK server, which is the robot's own process (the
  robot restarts with it, as a robot process with an embedded server does);
* ``rosbridge``: ``rosbridge_server_rs`` only; the ROS 2 graph (the robot's
  rclpy node) stays;
* ``zenoh``: the eclipse-zenoh router only; the robot's zenoh-ros2-sdk nodes
  are zenoh peers (as rmw_zenoh's nodes are) and stay up: they reconnect to
  the router by themselves when it returns, as a deployment's nodes do.

Reported per run (a table, and ``--json``): the client's memory (RSS sampled
every ``SAMPLE_S`` seconds: the median of the last fifth of the samples
against the first fifth), its file descriptors and threads at the end against
the start (both taken while connected), the delivery of camera and odometry in
each life of the peer, control publishes that returned normally and never
arrived (each classified by when it was written relative to the kill before
it), and the control publish p99. ``--trace-memory`` runs the client under
``tracemalloc`` and prints the allocation sites that grew most between a
snapshot at the end of the first fifth and one at the end.
"""

from __future__ import annotations

import argparse
import bisect
import gc
import itertools
import json
import math
import os
import platform
import shutil
import signal
import statistics
import struct
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any, Final

HERE: Final = Path(__file__).resolve().parent
ROOT: Final = HERE.parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(ROOT / "tests"))

from _common import LOOPS, run_on  # noqa: E402
from _soak_robot import CAMERA_TOPIC, CMD_TOPIC, ODOM_TOPIC  # noqa: E402

ROBOT: Final = HERE / "_soak_robot.py"
TRANSPORTS: Final = ("foxglove", "rosbridge", "zenoh")
CONTROL_HZ: Final = 20.0
SAMPLE_S: Final = 2.0
SETTLE_S: Final = 20.0
"""A kill is not made in the last SETTLE_S seconds, so the run ends connected."""
READY_TIMEOUT: Final = 60.0
IN_FLIGHT: Final = "written before the peer died, not yet handled by it"
DOWN: Final = "written after the peer died, before it returned"
ROUTE: Final = "written before the route to the robot was up again"
CLOSED: Final = "written before a connection the peer closed (not a kill)"
END: Final = "written before the client closed, not yet handled by the peer"
UNEXPLAINED: Final = "unexplained: later publishes arrived on the same connection"
EXPLAINED: Final = (IN_FLIGHT, DOWN, ROUTE, CLOSED, END)
"""The classes of a lost control publish that a connection's end explains:
TCP (or a zenoh put) returned, and the peer died or closed with it unhandled."""


def monotonic() -> float:
    return time.monotonic()


# -- the client (a process of its own: python bench/soak.py --client CONFIG) ------------------


def rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def os_threads() -> int:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("Threads:"):
                return int(line.split()[1])
    return 0


def fds() -> int:
    return len(os.listdir("/proc/self/fd"))


async def client_run(cfg: dict[str, Any], records: IO[str]) -> dict[str, Any]:
    import tracemalloc

    import anyio

    import ros_mobile_bridge as rmb
    from ros_mobile_bridge.interfaces.geometry_msgs.msg import Twist, Vector3
    from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry
    from ros_mobile_bridge.interfaces.sensor_msgs.msg import Image

    options = rmb.ClientOptions(
        reconnect=rmb.ReconnectPolicy(initial_delay=0.2, max_delay=2.0),
        domain_id=cfg.get("domain"),
    )
    from _common import subscription_counts

    received = {"cam": [0], "odom": [0]}  # messages so far
    counts: dict[str, dict[str, int]] = {}
    raw = {"cam": 0, "odom": 0}  # delivered undecoded (a memoryview)
    wake = [anyio.Event()]  # set on every message and status change

    async def until(predicate: Callable[[], bool]) -> None:
        with anyio.fail_after(READY_TIMEOUT):
            while not predicate():
                wake[0] = anyio.Event()
                await wake[0].wait()

    samples: list[tuple[float, int, int, int]] = []
    statuses: list[tuple[float, str]] = []
    tracing = bool(cfg["trace_memory"])
    snapshots: list[Any] = []
    start = monotonic()
    duration = float(cfg["seconds"])

    async with rmb.connect(cfg["url"], protocol=cfg["protocol"], options=options) as robot:

        async def consume(name: str, topic: str, cls: Any) -> None:
            # rosbridge: the bridge sends CDR in CBOR, as the docs advise for
            # images (JSON base64 at 30 Hz saturates the bridge); ignored elsewhere
            async with robot.subscribe(topic, cls, compression="cbor-raw") as sub:
                out = received[name]
                write = records.write
                try:
                    async for msg in sub:
                        data = msg.data
                        if isinstance(data, memoryview):  # delivered raw: not decoded
                            raw[name] += 1
                            stamp = raw_stamp(data)
                            if stamp is None:
                                continue
                            sec, nanosec = stamp
                        else:
                            sec, nanosec = data.header.stamp.sec, data.header.stamp.nanosec
                        write(f"r {name} {sec} {nanosec} {monotonic():.6f}\n")
                        out[0] += 1
                        wake[0].set()
                finally:
                    counts[name] = subscription_counts(sub)

        async def control() -> None:
            seq = 0
            due = monotonic()
            period = 1.0 / CONTROL_HZ
            while True:
                now = monotonic()
                if due > now:
                    await anyio.sleep(due - now)
                seq += 1
                due += period
                t0 = monotonic()
                try:
                    await robot.publish(
                        CMD_TOPIC,
                        Twist(linear=Vector3(x=0.0, y=float(seq)), angular=Vector3()),
                        priority="control",
                    )
                    outcome = "ok"
                except rmb.RosBridgeError as exc:
                    outcome = type(exc).__name__
                records.write(f"p {seq} {t0:.6f} {monotonic() - t0:.6f} {outcome}\n")

        async def watch() -> None:
            async for status in robot.watch_status():
                statuses.append((monotonic(), str(status)))
                wake[0].set()

        def sample() -> tuple[float, int, int, int]:
            return (monotonic() - start, rss_bytes(), fds(), os_threads())

        async def sampler() -> None:
            collect, last_collect = float(cfg.get("gc_every") or 0), monotonic()
            while True:
                if collect and monotonic() - last_collect >= collect:
                    gc.collect()
                    last_collect = monotonic()
                samples.append(sample())
                await anyio.sleep(SAMPLE_S)

        async with anyio.create_task_group() as tg:
            tg.start_soon(watch)
            tg.start_soon(consume, "cam", CAMERA_TOPIC, Image)
            tg.start_soon(consume, "odom", ODOM_TOPIC, Odometry)
            await until(lambda: received["cam"][0] > 0 and received["odom"][0] > 0)
            tg.start_soon(control)
            await anyio.sleep(1.0)
            first = sample()
            print("ready", flush=True)  # the parent counts the kill schedule from here
            tg.start_soon(sampler)
            if tracing:
                tracemalloc.start(int(cfg["trace_frames"]))
                await anyio.sleep(duration / 5)
                snapshots.append(tracemalloc.take_snapshot())
                await anyio.sleep(duration * 4 / 5)
            else:
                await anyio.sleep(duration)
            # the end's figures are taken while connected and receiving again
            mark = (received["cam"][0], received["odom"][0])
            await until(
                lambda: (
                    robot.status == "connected"
                    and received["cam"][0] > mark[0]
                    and received["odom"][0] > mark[1]
                )
            )
            if tracing:
                snapshots.append(tracemalloc.take_snapshot())
            last = sample()
            tg.cancel_scope.cancel()
        statuses.append((monotonic(), "closed"))  # the client leaves: its close begins
    closed = sample()
    growth: list[dict[str, Any]] = []
    if tracing:
        growth = trace_growth(snapshots[0], snapshots[1])
        tracemalloc.stop()
    return {
        "start": start,
        "first": first,
        "last": last,
        "closed": closed,
        "samples": samples,
        "statuses": statuses,
        "growth": growth,
        "subscriptions": counts,
        "raw": raw,
    }


def raw_stamp(data: memoryview) -> tuple[int, int] | None:
    """``header.stamp`` of a message delivered raw, when it is little-endian
    CDR (the stamp is its first field); None otherwise."""
    if data.nbytes >= 12 and bytes(data[:2]) == b"\x00\x01":
        sec, nanosec = struct.unpack_from("<iI", data, 4)
        return int(sec), int(nanosec)
    return None


def trace_growth(before: Any, after: Any, top: int = 25) -> list[dict[str, Any]]:
    """The allocation sites that grew most from ``before`` to ``after`` (each
    with its innermost frames), tracemalloc's own allocations left out."""
    import tracemalloc

    keep = [tracemalloc.Filter(False, tracemalloc.__file__)]
    stats = after.filter_traces(keep).compare_to(before.filter_traces(keep), "traceback")
    return [
        {
            "size_diff": s.size_diff,
            "count_diff": s.count_diff,
            "size": s.size,
            "where": [f"{f.filename}:{f.lineno}" for f in s.traceback],
        }
        for s in stats[:top]
    ]


def client_main(config: str) -> None:
    cfg = json.loads(config)
    # every record goes to a file as it is made (none is kept in memory: the
    # client's memory is the library's); the file is open from start to end
    with open(cfg["records"], "w", buffering=1 << 16) as records:
        result = run_on(cfg["loop"], client_run, cfg, records)
    Path(cfg["out"]).write_text(json.dumps(result))
    print("done", flush=True)


def read_records(path: Path) -> dict[str, Any]:
    """The client's records file: ``received`` (per stream, (run, seq,
    time) of every message) and ``publishes`` ((seq, start, seconds,
    outcome) of every control publish)."""
    received: dict[str, list[tuple[int, int, float]]] = {"cam": [], "odom": []}
    publishes: list[tuple[int, float, float, str]] = []
    with path.open() as f:
        for line in f:
            words = line.split()
            if words[0] == "r":
                received[words[1]].append((int(words[2]), int(words[3]), float(words[4])))
            elif words[0] == "p":
                publishes.append((int(words[1]), float(words[2]), float(words[3]), words[4]))
    return {"received": received, "publishes": publishes}


# -- the robot side and the peer's lives ------------------------------------------------------


class Lines:
    """A process's stdout lines, read by a thread: ``cam``/``odom``/``cmd``
    records go to ``sink``, the rest to a list."""

    def __init__(self, stream: IO[str], sink: Callable[[str, int, float], None]) -> None:
        self.other: list[str] = []
        self.ready = threading.Event()
        self._sink = sink
        self.thread = threading.Thread(target=self._read, args=(stream,), daemon=True)
        self.thread.start()

    def _read(self, stream: IO[str]) -> None:
        for line in stream:
            words = line.split()
            if len(words) == 3 and words[0] in ("cam", "odom", "cmd"):
                self._sink(words[0], int(words[1]), float(words[2]))
            elif words == ["ready"]:
                self.ready.set()
            else:
                self.other.append(line)
                del self.other[:-50]


@dataclass
class Life:
    """One life of the peer the client is connected to."""

    ready: float
    killed: float | None = None
    started: float = 0.0


@dataclass
class World:
    """The robot and the peer, with everything the robot reported."""

    transport: str
    port: int
    lives: list[Life] = field(default_factory=list)
    published: dict[str, list[tuple[int, int, float]]] = field(
        default_factory=lambda: {"cam": [], "odom": []}
    )
    commands: dict[int, float] = field(default_factory=dict)
    run: int = 0
    _robots: list[tuple[subprocess.Popen[str], Lines]] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stack: list[Callable[[], None]] = field(default_factory=list)
    peer_env: Any = None
    graph_domain: int = 0
    router: Any = None
    bridge: Any = None

    @property
    def url(self) -> str:
        if self.transport == "zenoh":
            return f"tcp/127.0.0.1:{self.port}"
        return f"ws://127.0.0.1:{self.port}"

    def _sink(self, run: int) -> Callable[[str, int, float], None]:
        def sink(kind: str, seq: int, t: float) -> None:
            with self._lock:
                if kind == "cmd":
                    self.commands.setdefault(seq, t)
                else:
                    self.published[kind].append((run, seq, t))

        return sink

    def _robot(self, argv: list[str], env: dict[str, str] | None = None) -> None:
        self.run += 1
        from peers.rosbridge import _die_with_parent

        proc = subprocess.Popen(
            [*argv, str(self.run)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=env,
            preexec_fn=_die_with_parent,
        )
        assert proc.stdout is not None
        lines = Lines(proc.stdout, self._sink(self.run))
        self._robots.append((proc, lines))
        if not lines.ready.wait(READY_TIMEOUT):
            raise RuntimeError(f"the robot did not start: {argv} {lines.other[-5:]}")

    def start(self) -> None:
        """Start the robot and the peer (first life)."""
        from peers.rosbridge import free_port

        self.port = free_port()
        t0 = monotonic()
        if self.transport == "foxglove":
            self._start_peer()
        elif self.transport == "rosbridge":
            from peers.ros_env import ensure_peer_env
            from peers.rosbridge import random_domain_id

            self.peer_env = ensure_peer_env()
            self.graph_domain = random_domain_id()
            env = self.peer_env.node_env(self.graph_domain)
            self._robot([str(self.peer_env.python), str(ROBOT), "ros"], env)
            self._start_peer()
        else:
            from peers.ros_env import ensure_peer_env
            from peers.rosbridge import random_domain_id

            self.peer_env = ensure_peer_env()
            self.graph_domain = random_domain_id()
            self._start_peer()
            self._robot(
                [
                    sys.executable,
                    str(ROBOT),
                    "zenoh",
                    self.url,
                    str(self.graph_domain),
                    str(self.peer_env.prefix / "share"),
                ]
            )
        self.lives[-1].started = t0

    def _start_peer(self) -> None:
        t0 = monotonic()
        if self.transport == "foxglove":
            self._robot([sys.executable, str(ROBOT), "foxglove", str(self.port)])
        elif self.transport == "rosbridge":
            from peers.rosbridge import RosBridge

            topics = (
                (CAMERA_TOPIC, "sensor_msgs/msg/Image"),
                (ODOM_TOPIC, "nav_msgs/msg/Odometry"),
                (CMD_TOPIC, "geometry_msgs/msg/Twist"),
            )
            for attempt in range(20):  # the port may still be held for a moment
                try:
                    self.bridge = RosBridge.start(
                        self.peer_env,
                        self.graph_domain,
                        port=self.port,
                        wait_topics=topics,
                        wait_services=(),
                        wait_actions=(),
                    )
                    break
                except Exception:
                    if attempt == 19:
                        raise
                    time.sleep(0.25)
        else:
            from peers.zenoh_router import ZenohRouter

            for attempt in range(20):
                try:
                    self.router = ZenohRouter(self.port).start()
                    break
                except RuntimeError:
                    if attempt == 19:
                        raise
                    time.sleep(0.25)
        self.lives.append(Life(ready=monotonic(), started=t0))

    def kill(self) -> None:
        """SIGKILL the peer (a crash), then start it again on the same port."""
        t = monotonic()
        if self.transport == "foxglove":
            proc, _ = self._robots[-1]
            proc.kill()
        elif self.transport == "rosbridge":
            assert self.bridge is not None
            assert self.bridge.proc is not None
            self.bridge.proc.kill()
        else:
            assert self.router is not None
            assert self.router._proc is not None
            self.router._proc.kill()
        self.lives[-1].killed = t
        self._reap()
        self._start_peer()

    def _reap(self) -> None:
        if self.transport == "foxglove":
            proc, lines = self._robots[-1]
            proc.wait()
            lines.thread.join(5)
            for stream in (proc.stdin, proc.stdout):
                if stream is not None:
                    stream.close()
        elif self.transport == "rosbridge":
            self.bridge.stop()
        else:
            self.router.stop()

    def stop(self) -> None:
        for proc, lines in self._robots:
            if proc.poll() is None:
                assert proc.stdin is not None
                proc.stdin.close()
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
            lines.thread.join(5)
        if self.bridge is not None:
            self.bridge.stop()
        if self.router is not None:
            self.router.stop()


# -- the run and its report ---------------------------------------------------------------------


def percentile(values: list[float], q: float) -> float:
    if not values:
        return float("nan")
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def fifth_medians(samples: list[list[float]]) -> tuple[float, float]:
    n = max(1, len(samples) // 5)
    return (
        statistics.median(s[1] for s in samples[:n]),
        statistics.median(s[1] for s in samples[-n:]),
    )


def analyse(world: World, client: dict[str, Any], args: argparse.Namespace) -> dict[str, Any]:
    """Everything the report shows, from the robot's and the client's records."""
    lives = world.lives
    stop = client["start"] + client["last"][0]  # the client's end figures
    # delivery per life: the robot's messages published while the peer lived
    per_life: list[dict[str, Any]] = []
    got = {k: {(r, s) for r, s, _ in client["received"][k]} for k in ("cam", "odom")}
    first_rx = {k: sorted(client["received"][k], key=lambda x: x[2]) for k in ("cam", "odom")}
    for i, life in enumerate(lives):
        end = life.killed if life.killed is not None else stop
        row: dict[str, Any] = {"life": i + 1, "seconds": end - life.ready}
        for kind in ("cam", "odom"):
            mine = [(r, s, t) for r, s, t in world.published[kind] if life.ready <= t < end]
            received = [m for m in mine if (m[0], m[1]) in got[kind]]
            rx_times = [t for r, s, t in first_rx[kind] if life.ready <= t < end]
            since = [m for m in mine if received and m[2] >= received[0][2]]
            row[kind] = {
                "published": len(mine),
                "received": len(received),
                "since_first": len(since),
                "delivered": len(received) / len(since) if since else 0.0,
                "first_after_s": (rx_times[0] - life.ready) if rx_times else None,
            }
        per_life.append(row)
    # control: returned and never arrived, each classified (see classify_lost)
    durations = [dur * 1000.0 for _, _, dur, _ in client["publishes"]]
    outcomes: dict[str, int] = {}
    for _, _, _, outcome in client["publishes"]:
        outcomes[outcome] = outcomes.get(outcome, 0) + 1
    lost = classify_lost(client["publishes"], world.commands, lives, client["statuses"])
    latency = [
        (world.commands[seq] - (t0 + dur)) * 1000.0
        for seq, t0, dur, outcome in client["publishes"]
        if outcome == "ok" and seq in world.commands
    ]
    arrivals = sorted(world.commands.values())
    for row, life in zip(per_life, lives, strict=True):
        end = life.killed if life.killed is not None else stop
        mine = [t for t in arrivals if life.ready <= t < end]
        row["cmd"] = {
            "arrived": len(mine),
            "first_after_s": (mine[0] - life.ready) if mine else None,
        }
    rss_first, rss_last = fifth_medians(client["samples"])
    first, last, closed = client["first"], client["last"], client["closed"]
    classes: dict[str, int] = {}
    for entry in lost:
        classes[entry["class"]] = classes.get(entry["class"], 0) + 1
    return {
        "transport": args.transport,
        "loop": args.loop,
        "minutes": args.minutes,
        "kill_every": args.kill_every,
        "kills": sum(1 for lf in lives if lf.killed is not None),
        "memory": {
            "rss_first_fifth_mb": rss_first / 1e6,
            "rss_last_fifth_mb": rss_last / 1e6,
            "growth_mb": (rss_last - rss_first) / 1e6,
            "growth_mb_per_hour": (rss_last - rss_first) / 1e6 * 60.0 / max(args.minutes, 1e-9),
            "peak_mb": max(s[1] for s in client["samples"]) / 1e6,
        },
        "fds": {"start": first[2], "end": last[2], "closed": closed[2]},
        "threads": {"start": first[3], "end": last[3], "closed": closed[3]},
        "lives": per_life,
        "control": {
            "published": len(client["publishes"]),
            "outcomes": outcomes,
            "returned_not_arrived": len(lost),
            "lost_by_class": classes,
            "lost": lost,
            "p50_ms": percentile(durations, 0.5),
            "p99_ms": percentile(durations, 0.99),
            "max_ms": max(durations) if durations else float("nan"),
            "arrival_p50_ms": percentile(latency, 0.5),
            "arrival_p99_ms": percentile(latency, 0.99),
        },
        "subscriptions": client.get("subscriptions", {}),
        "delivered_raw": client.get("raw", {}),
        "statuses": client["statuses"],
        "rss_samples": [[round(s[0], 1), s[1]] for s in client["samples"]],
        "memory_growth_sites": client["growth"],
    }


def classify_lost(
    publishes: list[list[Any]],
    arrived: dict[int, float],
    lives: list[Life],
    statuses: list[list[Any]],
) -> list[dict[str, Any]]:
    """Every control publish that returned normally and never reached the
    robot, with its class: the first that applies of

    * a kill between the last publish that arrived before it and the next
      one that arrived after it: written before the kill (:data:`IN_FLIGHT`:
      in the peer's socket or queue when it died), between the kill and the
      peer's return (:data:`DOWN`: written into a socket whose peer had died
      before the close was read, or, over Zenoh, put while the router was
      gone), or after the return (:data:`ROUTE`);
    * a connection loss the client saw (not a kill) after it, before the
      next one that arrived (:data:`CLOSED`: the peer closed the connection
      with it unhandled);
    * nothing arrived between the start of its connection (the client's
      last ``connected``, or the peer's return) and it (:data:`ROUTE`: the
      first publishes after a (re)connection, before the bridge's or the
      router's route to the robot's subscriber exists);
    * no later publish arrived, and the client closed after it (:data:`END`:
      still queued in the peer when the client left, which ends the
      connection and what the peer had not handled);
    * else :data:`UNEXPLAINED`: a loss in the middle of a working connection.
    """
    written = {seq: t0 + dur for seq, t0, dur, outcome in publishes if outcome == "ok"}
    arrivals = sorted(written[seq] for seq in arrived if seq in written)
    kills = [
        (lf.killed, nxt.ready) for lf, nxt in itertools.pairwise(lives) if lf.killed is not None
    ]
    losses = [t for t, status in statuses if status == "reconnecting"]
    closes = [t for t, status in statuses if status == "closed"]
    epochs = sorted(
        [t for t, status in statuses if status == "connected"] + [lf.ready for lf in lives]
    )
    lost = []
    for seq, w in sorted(written.items()):
        if seq in arrived:
            continue
        i = bisect.bisect_left(arrivals, w)
        prev = arrivals[i - 1] if i else -math.inf
        nxt = arrivals[i] if i < len(arrivals) else math.inf
        entry: dict[str, Any] = {"seq": seq, "written": w}
        between = [(k, back) for k, back in kills if prev < k < nxt]
        if between:
            kill, back = between[-1] if between[-1][0] <= w else between[0]
            entry["after_kill_ms"] = (w - kill) * 1000.0
            entry["class"] = IN_FLIGHT if w < kill else DOWN if w < back else ROUTE
        elif any(w <= t < nxt for t in losses):
            entry["class"] = CLOSED
        elif nxt == math.inf and closes and closes[-1] >= w:
            entry["class"] = END
        else:
            j = bisect.bisect_right(epochs, w)
            entry["class"] = ROUTE if j and prev < epochs[j - 1] else UNEXPLAINED
        lost.append(entry)
    return lost


def print_report(r: dict[str, Any]) -> None:
    m = r["memory"]
    print(
        f"\nsoak: {r['transport']} on {r['loop']}, {r['minutes']} min, peer killed every "
        f"{r['kill_every']} s ({r['kills']} kills)"
    )
    print(
        f"  client RSS  first fifth {m['rss_first_fifth_mb']:.1f} MB -> last fifth "
        f"{m['rss_last_fifth_mb']:.1f} MB: {m['growth_mb']:+.1f} MB "
        f"({m['growth_mb_per_hour']:+.1f} MB/h), peak {m['peak_mb']:.1f} MB"
    )
    print(
        f"  fds         {r['fds']['start']} -> {r['fds']['end']} (after close {r['fds']['closed']})"
    )
    print(
        f"  threads     {r['threads']['start']} -> {r['threads']['end']}"
        f" (after close {r['threads']['closed']})"
    )
    c = r["control"]
    print(
        f"  control     {c['published']} publishes {c['outcomes']}; p50 {c['p50_ms']:.2f} ms,"
        f" p99 {c['p99_ms']:.2f} ms, max {c['max_ms']:.1f} ms"
    )
    print(
        f"  arrival     publish returned -> robot's receipt: p50 {c['arrival_p50_ms']:.2f} ms,"
        f" p99 {c['arrival_p99_ms']:.2f} ms"
    )
    for name, counts in r["subscriptions"].items():
        print(f"  {name:<11} {counts}")
    if any(r["delivered_raw"].values()):
        print(f"  delivered raw (not decoded): {r['delivered_raw']}")
    print(f"  returned, never arrived: {c['returned_not_arrived']} {c['lost_by_class']}")
    for entry in c["lost"][:20]:
        extra = ""
        if "after_kill_ms" in entry:
            extra = f", {entry['after_kill_ms']:+.1f} ms from the kill"
        print(f"    seq {entry['seq']}: {entry['class']}{extra}")
    print(
        "  life   secs |  camera rx/pub  since-1st  first-s |  odom rx/pub  since-1st  first-s"
        " | cmd arrived  first-s"
    )
    for row in r["lives"]:
        cells = []
        for kind in ("cam", "odom"):
            d = row[kind]
            first = "-" if d["first_after_s"] is None else f"{d['first_after_s']:.2f}"
            cells.append(
                f"{d['received']:6d}/{d['published']:<6d} {d['delivered'] * 100:6.1f}%  {first:>7}"
            )
        cmd = row["cmd"]
        first = "-" if cmd["first_after_s"] is None else f"{cmd['first_after_s']:.2f}"
        cells.append(f"{cmd['arrived']:11d}  {first:>7}")
        print(f"  {row['life']:4d} {row['seconds']:6.1f} | " + " | ".join(cells))
    if r["memory_growth_sites"]:
        print("  tracemalloc: the sites that grew most from the end of the first fifth to the end")
        for site in r["memory_growth_sites"][:15]:
            print(
                f"    {site['size_diff'] / 1024:+9.1f} KiB {site['count_diff']:+7d} blocks"
                f"  {' <- '.join(reversed(site['where'][-3:]))}"
            )


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--transport", choices=TRANSPORTS, default="foxglove")
    parser.add_argument("--loop", choices=LOOPS, default="asyncio")
    parser.add_argument("--minutes", type=float, default=60.0)
    parser.add_argument("--kill-every", type=float, default=120.0, help="seconds; 0: never")
    parser.add_argument("--json", type=Path, default=None)
    parser.add_argument("--trace-memory", action="store_true")
    parser.add_argument("--trace-frames", type=int, default=6)
    parser.add_argument(
        "--gc-every",
        type=float,
        default=0.0,
        help="a diagnostic: a full gc.collect() in the client every S seconds (0: never)",
    )
    parser.add_argument("--client", default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.client is not None:
        client_main(args.client)
        return 0
    # SIGTERM (and SIGINT, ignored in a background job) stop the run cleanly
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    seconds = args.minutes * 60.0
    world = World(args.transport, 0)
    scratch = Path(tempfile.mkdtemp(prefix="rmb-soak-"))
    out, records = scratch / "client.json", scratch / "records.txt"
    client: subprocess.Popen[str] | None = None
    try:
        world.start()
        cfg = {
            "url": world.url,
            "protocol": {"foxglove": "foxglove-ws", "rosbridge": "rosbridge", "zenoh": "zenoh"}[
                args.transport
            ],
            "loop": args.loop,
            "seconds": seconds,
            "trace_memory": args.trace_memory,
            "trace_frames": args.trace_frames,
            "gc_every": args.gc_every,
            "out": str(out),
            "records": str(records),
            "domain": world.graph_domain if args.transport == "zenoh" else None,
        }
        paths = [str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in paths if p)}
        from peers.rosbridge import _die_with_parent

        client = subprocess.Popen(
            [sys.executable, __file__, "--client", json.dumps(cfg)],
            stdout=subprocess.PIPE,
            text=True,
            env=env,
            preexec_fn=_die_with_parent,
        )
        assert client.stdout is not None
        line = client.stdout.readline()
        if line.strip() != "ready":
            raise RuntimeError(f"the client did not start: {line!r} (exit {client.poll()})")
        t0 = monotonic()
        kills = 0
        while args.kill_every > 0:
            due = t0 + (kills + 1) * args.kill_every
            if due > t0 + seconds - SETTLE_S:
                break
            while monotonic() < due and client.poll() is None:
                time.sleep(min(0.2, max(0.0, due - monotonic())))
            if client.poll() is not None:
                break
            world.kill()
            kills += 1
            dead = world.lives[-2]
            assert dead.killed is not None
            print(
                f"  kill {kills} at {dead.killed - t0:.1f} s, back after"
                f" {world.lives[-1].ready - dead.killed:.2f} s",
                flush=True,
            )
        line = client.stdout.readline()
        code = client.wait()
        if line.strip() != "done" or code != 0:
            raise RuntimeError(f"the client failed (exit {code})")
        time.sleep(1.0)  # the last control messages reach the robot's records
        result = json.loads(out.read_text())
        result.update(read_records(records))
    finally:
        if client is not None and client.poll() is None:
            client.kill()
            client.wait()
        world.stop()
        shutil.rmtree(scratch, ignore_errors=True)
    report = analyse(world, result, args)
    report["machine"] = f"{platform.machine()}, {os.cpu_count()} CPUs, load {os.getloadavg()}"
    report["date"] = time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())
    print_report(report)
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
