"""A real ROS 2 graph and the Rust rosbridge v2 server, as subprocesses on
loopback (plain synchronous Python: usable from tests, fixtures and bench).

    peer = ensure_peer_env()
    with RosGraph.start(peer) as graph, RosBridge.start(peer, graph.domain_id) as bridge:
        bridge.url                      # ws://127.0.0.1:PORT, ready: the graph is discovered
        graph.command({"cmd": "received", "topic": "/rmb_in"})

:class:`RosGraph` runs ``ros_graph_node.py`` (see its docstring for the graph
and the commands) with the peer Python. :class:`RosBridge` runs
``rosbridge_server_rs_jazzy --bind 127.0.0.1:PORT`` on a free port and waits
until ``/rosapi`` shows the graph; several bridges (with other flags) can share
one graph. Every process is stopped by its own pid (terminate, wait, kill), by
``stop()``, the context manager, or at interpreter exit. Logs go to a
temporary directory; ``log_tail()`` shows their end for failure messages.
"""

from __future__ import annotations

import atexit
import contextlib
import ctypes
import itertools
import json
import os
import queue
import random
import shutil
import signal
import socket
import subprocess
import tempfile
import threading
import time
from collections.abc import Iterable, Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any

from websockets.sync.client import ClientConnection, connect

from peers.ros_env import PeerEnv, tail

GRAPH_SCRIPT = Path(__file__).resolve().parent / "ros_graph_node.py"

#: What a bridge must see before it counts as ready (the default graph).
READY_TOPICS: tuple[tuple[str, str], ...] = (
    ("/chatter", "std_msgs/msg/String"),
    ("/odom", "nav_msgs/msg/Odometry"),
    ("/counter", "std_msgs/msg/Int32"),
    ("/cmd_vel", "geometry_msgs/msg/Twist"),
    ("/rmb_in", "std_msgs/msg/String"),
)
READY_SERVICES: tuple[str, ...] = (
    "/set_flag",
    "/slow_trigger",
    "/rmb_params/get_parameters",
    "/rmb_params/list_parameters",
    "/rmb_params/set_parameters",
)
READY_ACTIONS: tuple[str, ...] = ("/fibonacci",)


class PeerProcessError(RuntimeError):
    """A peer process failed to start, died, or answered with an error."""


def random_domain_id(*, other_than: int | None = None) -> int:
    """A DDS domain for one test session (1..101), so parallel sessions on
    one machine do not see each other's graphs; never ``other_than`` (a
    graph to stay away from). The workers of one parallel run
    (pytest-xdist) each draw from their own residue class, so no two of
    them share a domain."""
    worker = os.environ.get("PYTEST_XDIST_WORKER", "")
    count = int(os.environ.get("PYTEST_XDIST_WORKER_COUNT", "1") or 1)
    index = int(worker.removeprefix("gw")) if worker.startswith("gw") else 0
    draw = random.SystemRandom()
    while True:
        if count <= 1 or count > 50:
            domain = draw.randint(1, 101)
        else:
            domain = 1 + index + count * draw.randrange(100 // count)
        if domain != other_than:
            return domain


def free_port() -> int:
    """A TCP port free on 127.0.0.1 right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# Every process started here, stopped at interpreter exit if still running.
_LIVE: set[_Process] = set()
_LIVE_LOCK = threading.Lock()


def _stop_all() -> None:
    with _LIVE_LOCK:
        procs = list(_LIVE)
    for p in procs:
        p.stop()


atexit.register(_stop_all)

_PR_SET_PDEATHSIG = 1


def _die_with_parent() -> None:  # runs in the child between fork and exec
    with contextlib.suppress(Exception):
        ctypes.CDLL(None).prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


class _Process:
    """A subprocess with a log directory, stopped by pid."""

    def __init__(self, name: str, log_dir: Path | None) -> None:
        self.name = name
        self._own_dir = log_dir is None
        self.log_dir = Path(tempfile.mkdtemp(prefix=f"rmb-{name}-")) if log_dir is None else log_dir
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.log_dir / f"{name}.log"
        self.proc: subprocess.Popen[bytes] | None = None
        self._log_file: IO[bytes] | None = None

    def _spawn(
        self, argv: Sequence[str | Path], env: dict[str, str], *, stdin: int | None = None
    ) -> subprocess.Popen[bytes]:
        env = dict(env)
        env.setdefault("ROS_LOG_DIR", str(self.log_dir / "ros"))
        self._log_file = open(self.log_path, "ab")  # noqa: SIM115 - closed by stop()
        # The child gets SIGTERM if this thread dies (only from the main
        # thread: a worker thread's exit would kill it early).
        in_main = threading.current_thread() is threading.main_thread()
        self.proc = subprocess.Popen(
            [str(a) for a in argv],
            stdin=subprocess.DEVNULL if stdin is None else stdin,
            stdout=subprocess.PIPE if stdin is not None else self._log_file,
            stderr=self._log_file,
            env=env,
            preexec_fn=_die_with_parent if in_main else None,
        )
        with _LIVE_LOCK:
            _LIVE.add(self)
        return self.proc

    @property
    def pid(self) -> int | None:
        return None if self.proc is None else self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def log_tail(self, lines: int = 60) -> str:
        """The end of this process's log (stderr, and stdout for the bridge)."""
        return tail(self.log_path, lines)

    def _failure(self, what: str) -> PeerProcessError:
        code = None if self.proc is None else self.proc.poll()
        state = "running" if code is None else f"exit code {code}"
        return PeerProcessError(
            f"{self.name} (pid {self.pid}, {state}): {what}\n"
            f"--- last lines of {self.log_path} ---\n{self.log_tail()}"
        )

    def _ask_to_stop(self) -> bool:
        """Ask the process to end by itself; False if it has no such way."""
        return False

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the process (idempotent): its own way if it has one, then
        SIGTERM, then SIGKILL, each waited for up to ``timeout``."""
        proc = self.proc
        if proc is not None and proc.poll() is None:
            asked = False
            with contextlib.suppress(Exception):
                asked = self._ask_to_stop()
            try:
                if not asked:
                    raise subprocess.TimeoutExpired(proc.args, 0)
                proc.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(timeout=timeout)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait(timeout=timeout)
        if proc is not None:
            for stream in (proc.stdin, proc.stdout):
                if stream is not None:
                    with contextlib.suppress(OSError):
                        stream.close()
        if self._log_file is not None:
            self._log_file.close()
            self._log_file = None
        with _LIVE_LOCK:
            _LIVE.discard(self)
        if self._own_dir and not os.environ.get("RMB_KEEP_PEER_LOGS"):
            shutil.rmtree(self.log_dir, ignore_errors=True)


class RosGraph(_Process):
    """The test graph (``ros_graph_node.py``) in its own process.

    Use :meth:`start`; :meth:`command` sends one command and returns its
    ``result`` (thread-safe)."""

    def __init__(self, peer: PeerEnv, domain_id: int, log_dir: Path | None = None) -> None:
        super().__init__("ros-graph", log_dir)
        self.peer = peer
        self.domain_id = domain_id
        self._lines: queue.Queue[bytes | None] = queue.Queue()
        self._lock = threading.Lock()
        self._broken: str | None = None

    @classmethod
    def start(
        cls,
        peer: PeerEnv,
        domain_id: int | None = None,
        *,
        log_dir: Path | None = None,
        timeout: float = 30.0,
    ) -> RosGraph:
        """Start the graph node (on a random domain unless given) and wait
        until it says its nodes are up."""
        graph = cls(peer, random_domain_id() if domain_id is None else domain_id, log_dir)
        try:
            graph._start(timeout)
        except BaseException:
            graph.stop()
            raise
        return graph

    def _start(self, timeout: float) -> None:
        env = self.peer.node_env(self.domain_id)
        env["PYTHONUNBUFFERED"] = "1"
        proc = self._spawn([self.peer.python, GRAPH_SCRIPT], env, stdin=subprocess.PIPE)
        threading.Thread(
            target=self._read, args=(proc.stdout,), name="ros-graph-reader", daemon=True
        ).start()
        line = self._next_line(timeout)
        try:
            hello = json.loads(line)
        except ValueError:
            hello = None
        if not (isinstance(hello, dict) and hello.get("ready")):
            raise self._failure(f"expected the ready line, got {line!r}")

    def _read(self, stream: IO[bytes] | None) -> None:
        assert stream is not None
        with contextlib.suppress(OSError, ValueError):
            for line in stream:
                self._lines.put(line)
        self._lines.put(None)

    def _next_line(self, timeout: float) -> bytes:
        try:
            line = self._lines.get(timeout=timeout)
        except queue.Empty:
            raise self._failure(f"no answer within {timeout} s") from None
        if line is None:
            self._lines.put(None)  # every later reader sees the end too
            raise self._failure("the graph node exited")
        return line

    def command(self, request: dict[str, Any], *, timeout: float = 15.0) -> Any:
        """Send one command (see ``ros_graph_node.py``) and return its result;
        raises :class:`PeerProcessError` if the node answers an error or not
        at all."""
        with self._lock:
            if self._broken is not None:
                raise PeerProcessError(f"the graph node is unusable: {self._broken}")
            proc = self.proc
            if proc is None or proc.stdin is None or proc.poll() is not None:
                raise self._failure("the graph node is not running")
            try:
                proc.stdin.write(json.dumps(request).encode() + b"\n")
                proc.stdin.flush()
                answer = json.loads(self._next_line(timeout))
            except (OSError, PeerProcessError) as exc:
                self._broken = str(exc).splitlines()[0]
                raise
        if not answer.get("ok"):
            raise PeerProcessError(f"graph command {request!r} failed: {answer.get('error')}")
        return answer.get("result")

    def received(self, topic: str) -> list[Any]:
        """The messages the graph recorded on ``topic`` (dicts)."""
        return list(self.command({"cmd": "received", "topic": topic}))

    def _ask_to_stop(self) -> bool:
        proc = self.proc
        if proc is None or proc.stdin is None:
            return False
        with self._lock:  # not in the middle of another command's line
            with contextlib.suppress(OSError):
                proc.stdin.write(b'{"cmd":"quit"}\n')
                proc.stdin.close()
        return True

    def __enter__(self) -> RosGraph:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


class RosBridge(_Process):
    """``rosbridge_server_rs_jazzy`` on 127.0.0.1, started with
    :meth:`start`; ``url`` is ``ws://127.0.0.1:PORT``."""

    def __init__(
        self,
        peer: PeerEnv,
        domain_id: int,
        port: int,
        extra_args: Sequence[str],
        log_dir: Path | None = None,
    ) -> None:
        super().__init__(f"rosbridge-{port}", log_dir)
        self.peer = peer
        self.domain_id = domain_id
        self.port = port
        self.extra_args = tuple(extra_args)
        self.url = f"ws://127.0.0.1:{port}"
        self._ids = itertools.count(1)

    @classmethod
    def start(
        cls,
        peer: PeerEnv,
        domain_id: int,
        *extra_args: str,
        port: int | None = None,
        log_dir: Path | None = None,
        wait_topics: Iterable[tuple[str, str]] = READY_TOPICS,
        wait_services: Iterable[str] = READY_SERVICES,
        wait_actions: Iterable[str] = READY_ACTIONS,
        timeout: float = 45.0,
    ) -> RosBridge:
        """Start a bridge on ``domain_id`` with extra command-line flags (for
        example ``"--fragment-timeout", "2"``) and wait until it accepts a
        WebSocket and ``/rosapi`` lists the given topics (name, type),
        services and action servers (pass empty ones when the graph is not the
        default one, or ``--no-rosapi`` is given). A free port is picked unless
        given (and retried if another process takes it first)."""
        attempts = 1 if port is not None else 3
        for attempt in range(attempts):
            bridge = cls(
                peer, domain_id, free_port() if port is None else port, extra_args, log_dir
            )
            try:
                bridge._start()
                bridge.wait_ready(
                    topics=wait_topics,
                    services=wait_services,
                    actions=wait_actions,
                    timeout=timeout,
                )
                return bridge
            except PeerProcessError as exc:
                bridge.stop()
                lost_port = "Address already in use" in str(exc) or "AddrInUse" in str(exc)
                if not lost_port or attempt == attempts - 1:
                    raise
        raise AssertionError("unreachable")

    def _start(self) -> None:
        argv = [
            self.peer.bridge,
            "--bind",
            f"127.0.0.1:{self.port}",
            "--log-ansi",
            "false",
            *self.extra_args,
        ]
        self._spawn(argv, self.peer.env(self.domain_id))

    def connect(self, **kwargs: Any) -> ClientConnection:
        """A new synchronous WebSocket client connection (no size limit)."""
        kwargs.setdefault("max_size", None)
        kwargs.setdefault("open_timeout", 5)
        return connect(self.url, **kwargs)

    def call_service(
        self,
        service: str,
        args: dict[str, Any] | None = None,
        *,
        timeout: float = 10.0,
        ws: ClientConnection | None = None,
    ) -> dict[str, Any]:
        """Call a service through the bridge (on ``ws``, else a connection of
        its own) and return the whole ``service_response`` frame. Frames for
        other requests on ``ws`` are skipped."""
        if ws is None:
            with self.connect() as own:
                return self.call_service(service, args, timeout=timeout, ws=own)
        call_id = f"rmb-peer-{next(self._ids)}"
        request: dict[str, Any] = {"op": "call_service", "service": service, "id": call_id}
        if args is not None:
            request["args"] = args
        ws.send(json.dumps(request))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no answer from {service} within {timeout} s")
            frame = ws.recv(timeout=left)
            if isinstance(frame, str):
                reply = json.loads(frame)
                if reply.get("id") == call_id:
                    return dict(reply)

    def wait_ready(
        self,
        *,
        topics: Iterable[tuple[str, str]] = READY_TOPICS,
        services: Iterable[str] = READY_SERVICES,
        actions: Iterable[str] = READY_ACTIONS,
        timeout: float = 45.0,
    ) -> None:
        """Poll until the bridge accepts a WebSocket and ``/rosapi`` shows
        the expected graph. New nodes take 1.5 to 2.5 s to be discovered."""
        want_topics = dict(topics)
        want_services = set(services)
        want_actions = set(actions)
        deadline = time.monotonic() + timeout
        # Its own "listening" line first: a port taken by another server must
        # not pass for this bridge being ready.
        listening = f"listening address=127.0.0.1:{self.port}"
        while listening not in tail(self.log_path, 200):
            if not self.alive():
                raise self._failure("the bridge exited during startup")
            if time.monotonic() > deadline:
                raise self._failure(f"no '{listening}' line within {timeout} s")
            time.sleep(0.05)
        missing: str | None = "a WebSocket connection"
        while time.monotonic() < deadline:
            if not self.alive():
                raise self._failure("the bridge exited during startup")
            try:
                with self.connect(open_timeout=2) as ws:
                    while time.monotonic() < deadline:
                        missing = self._missing(ws, want_topics, want_services, want_actions)
                        if missing is None:
                            return
                        time.sleep(0.25)
            except Exception as exc:  # not up yet, or rosapi not answering yet
                missing = f"a working connection ({type(exc).__name__}: {exc})"
                time.sleep(0.2)
        raise self._failure(f"not ready within {timeout} s: missing {missing}")

    def _missing(
        self,
        ws: ClientConnection,
        topics: dict[str, str],
        services: set[str],
        actions: set[str],
    ) -> str | None:
        if topics:
            values = self.call_service("/rosapi/topics", ws=ws)["values"]
            listed = dict(zip(values["topics"], values["types"], strict=True))
            absent = {t: ty for t, ty in topics.items() if listed.get(t) != ty}
            if absent:
                return f"topics {absent}"
        if services:
            listed_services = set(
                self.call_service("/rosapi/services", ws=ws)["values"]["services"]
            )
            if services - listed_services:
                return f"services {sorted(services - listed_services)}"
        if actions:
            reply = self.call_service("/rosapi/action_servers", ws=ws)
            if actions - set(reply["values"]["action_servers"]):
                return f"action servers {sorted(actions - set(reply['values']['action_servers']))}"
        return None

    def __enter__(self) -> RosBridge:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
