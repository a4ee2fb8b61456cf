"""An eclipse-zenoh router, in its own process, for the Zenoh tests.

Run as a script it opens a zenoh session in *router* mode listening on
``tcp/127.0.0.1:<port>`` only (multicast scouting and gossip off, shared
memory off, no plugins), prints ``READY <port>`` and serves until its stdin
closes or it gets SIGTERM. :class:`ZenohRouter` starts one on a free port and
stops it; the process also dies with its parent (``PR_SET_PDEATHSIG``).

A router may listen on ``tls/`` instead (``scheme="tls"``) and take any
other zenoh configuration keys (``settings``: key -> JSON value, inserted
after the defaults), e.g. its certificate and key, mutual TLS, a
user/password dictionary file, or ``connect/endpoints`` to link to another
router (:func:`tls_settings`, :func:`usrpwd_settings`).

    python tests/peers/zenoh_router.py 7447 [tcp|tls] ['{"key": value, ...}']
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Mapping
from pathlib import Path
from types import TracebackType

try:  # imported as tests/peers/zenoh_router.py or as peers.zenoh_router
    from peers.rosbridge import _die_with_parent, free_port
except ImportError:  # pragma: no cover - run as a script
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    from peers.rosbridge import _die_with_parent, free_port

READY = "READY"
START_TIMEOUT = 20.0


def router_config(
    port: int, scheme: str = "tcp", settings: Mapping[str, object] | None = None
) -> object:
    """A zenoh router config: one loopback endpoint (``scheme``: ``tcp`` or
    ``tls``), nothing discovered, then ``settings`` (key -> JSON value)."""
    import zenoh

    config = zenoh.Config()
    config.insert_json5("mode", '"router"')
    config.insert_json5("listen/endpoints", json.dumps([f"{scheme}/127.0.0.1:{port}"]))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("scouting/gossip/enabled", "false")
    config.insert_json5("transport/shared_memory/enabled", "false")
    for key, value in (settings or {}).items():
        config.insert_json5(key, json.dumps(value))
    return config


def tls_settings(
    cert_file: str, key_file: str, *, client_ca_file: str | None = None
) -> dict[str, object]:
    """Router settings for a ``tls/`` endpoint with this certificate and key;
    with ``client_ca_file``, mutual TLS: a client must show a certificate
    that CA signed."""
    tls = "transport/link/tls/"
    settings: dict[str, object] = {
        tls + "listen_certificate": cert_file,
        tls + "listen_private_key": key_file,
    }
    if client_ca_file is not None:
        settings[tls + "enable_mtls"] = True
        settings[tls + "root_ca_certificate"] = client_ca_file
    return settings


def usrpwd_settings(dictionary_file: str) -> dict[str, object]:
    """Router settings requiring user/password authentication against
    ``dictionary_file`` (``user:password`` lines)."""
    return {"transport/auth/usrpwd/dictionary_file": dictionary_file}


def serve(port: int, scheme: str = "tcp", settings: Mapping[str, object] | None = None) -> None:
    """Serve until stdin closes or SIGTERM / SIGINT."""
    import zenoh

    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    threading.Thread(target=lambda: (sys.stdin.read(), stop.set()), daemon=True).start()
    session = zenoh.open(router_config(port, scheme, settings))
    try:
        print(f"{READY} {port}", flush=True)
        stop.wait()
    finally:
        session.close()


class ZenohRouter:
    """A router process on 127.0.0.1: ``.port``, ``.locator``; a context
    manager (``stop()`` on exit, also when the test failed). ``scheme``
    (``tcp`` or ``tls``) and ``settings`` as in :func:`router_config`;
    ``start()`` again after ``stop()`` runs it on the same port."""

    def __init__(
        self,
        port: int | None = None,
        *,
        scheme: str = "tcp",
        settings: Mapping[str, object] | None = None,
    ) -> None:
        self.port = port or free_port()
        self.scheme = scheme
        self.settings = dict(settings or {})
        self.locator = f"{scheme}/127.0.0.1:{self.port}"
        self._proc: subprocess.Popen[str] | None = None

    def start(self) -> ZenohRouter:
        proc = subprocess.Popen(
            [sys.executable, __file__, str(self.port), self.scheme, json.dumps(self.settings)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            preexec_fn=_die_with_parent,
            env={**os.environ, "RUST_LOG": os.environ.get("RUST_LOG", "error")},
        )
        self._proc = proc
        line: list[str] = []
        reader = threading.Thread(
            target=lambda: line.append(proc.stdout.readline() if proc.stdout else "")
        )
        reader.start()
        reader.join(START_TIMEOUT)
        if not line or not line[0].startswith(READY):
            self.stop()
            raise RuntimeError(f"the zenoh router did not start on {self.locator}")
        return self

    @property
    def running(self) -> bool:
        return self._proc is not None and self._proc.poll() is None

    @property
    def pid(self) -> int:
        """The router process's id (to pause it with SIGSTOP, as a router
        that went silent)."""
        assert self._proc is not None, "the router is not running"
        return self._proc.pid

    def stop(self) -> int | None:
        """Stop the router (stdin closed, then SIGTERM, then SIGKILL); its exit code."""
        proc, self._proc = self._proc, None
        if proc is None:
            return None
        from peers._process import end_process  # this file also runs as a script

        return end_process(proc)

    def kill(self) -> int | None:
        """SIGKILL the router: it dies at once, closing no session first."""
        proc = self._proc
        if proc is not None and proc.poll() is None:
            proc.kill()
        return self.stop()

    def __enter__(self) -> ZenohRouter:
        return self.start()

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.stop()


if __name__ == "__main__":
    serve(
        int(sys.argv[1]),
        sys.argv[2] if len(sys.argv) > 2 else "tcp",
        json.loads(sys.argv[3]) if len(sys.argv) > 3 else None,
    )
