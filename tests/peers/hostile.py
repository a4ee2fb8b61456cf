"""Start, stop, kill and read the hostile server (``peers.hostile_server``,
trio + trio-websocket) as a subprocess, for the ``test_hostile_*`` tests.

    with HostileServer.start("chatter") as server:
        async with rmb.connect(server.url, ...) as robot: ...
        server.events("recv")   # what the client sent, as the server saw it

The server listens on a free 127.0.0.1 port (or a given one, to restart on
the same port), prints it, and logs one JSON object per line to a file
that :meth:`HostileServer.events` reads."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType
from typing import Any

TESTS = Path(__file__).resolve().parent.parent


class HostileServer:
    """One server process running one scenario."""

    def __init__(self, proc: subprocess.Popen[bytes], port: int, log: Path) -> None:
        self.proc = proc
        self.port = port
        self.log_path = log

    @property
    def pid(self) -> int:
        return self.proc.pid

    @property
    def url(self) -> str:
        return f"ws://127.0.0.1:{self.port}"

    @classmethod
    def start(
        cls,
        scenario: str,
        *,
        port: int = 0,
        log: Path | None = None,
        timeout: float = 20.0,
        **args: object,
    ) -> HostileServer:
        """Run ``scenario`` (a module of ``peers.hostile_scenarios``) with
        ``args`` (``--arg k=v``); return once it listens. ``log`` appends to
        an existing log (a restart); by default a new temporary file."""
        if log is None:
            fd, name = tempfile.mkstemp(prefix=f"hostile-{scenario}-", suffix=".jsonl")
            os.close(fd)
            log = Path(name)
        cmd = [
            sys.executable,
            "-m",
            "peers.hostile_server",
            scenario,
            "--port",
            str(port),
            "--log",
            str(log),
        ]
        for key, value in args.items():
            cmd += ["--arg", f"{key}={value}"]
        env = dict(
            os.environ, PYTHONPATH=str(TESTS) + os.pathsep + os.environ.get("PYTHONPATH", "")
        )
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, env=env, cwd=TESTS)
        assert proc.stdout is not None
        deadline = time.monotonic() + timeout
        line = b""
        while not line.endswith(b"\n"):
            left = deadline - time.monotonic()
            ready, _, _ = select.select([proc.stdout], [], [], max(left, 0))
            chunk = os.read(proc.stdout.fileno(), 256) if ready else b""
            if not chunk:
                proc.kill()
                proc.wait()
                raise RuntimeError(f"hostile server {scenario!r} did not start: {line!r}")
            line += chunk
        proc.stdout.close()
        word, number = line.split()[:2]
        assert word == b"PORT", line
        return cls(proc, int(number), log)

    def restart(self, scenario: str, **args: object) -> HostileServer:
        """A new server on the same port and log (after :meth:`kill`)."""
        return HostileServer.start(scenario, port=self.port, log=self.log_path, **args)

    def kill(self, sig: int = signal.SIGKILL) -> None:
        """Signal the process by pid (default SIGKILL) and reap it."""
        if self.proc.poll() is None:
            os.kill(self.proc.pid, sig)
        self.proc.wait(timeout=10)

    def stop(self) -> None:
        """SIGTERM, then SIGKILL after 5 s."""
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.kill()

    def events(self, event: str | None = None) -> list[dict[str, Any]]:
        """The server's log so far, optionally only entries named ``event``."""
        out = []
        for line in self.log_path.read_text(encoding="utf-8").splitlines():
            try:
                entry = json.loads(line)
            except ValueError:  # a line being written
                continue
            if event is None or entry.get("event") == event:
                out.append(entry)
        return out

    def received(self, op: str | None = None) -> list[dict[str, Any]]:
        """What clients sent (``recv`` entries), optionally only text ``op``."""
        return [e for e in self.events("recv") if op is None or e.get("op") == op]

    def __enter__(self) -> HostileServer:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()
        self.log_path.unlink(missing_ok=True)
