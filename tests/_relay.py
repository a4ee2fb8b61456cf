"""A reverse proxy in front of a real peer, built on ``websockets``' threaded
server (a library this project did not write): it records each handshake's
request headers and every message the client sends, may require a header
(answering 401 without it, as a token-checking proxy does), and relays the
WebSocket, subprotocol included, to the upstream server in both directions.

    with Relay(upstream_url, require=("authorization", "Bearer t")) as relay:
        relay.url           # ws://127.0.0.1:PORT
        relay.requests      # [Headers, ...], one per handshake
        relay.sent          # [str | bytes, ...], client -> server, in order
        relay.drop()        # close every client connection now (a lost link)
"""

from __future__ import annotations

import contextlib
import logging
import threading
from http import HTTPStatus
from typing import Any

import websockets
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.sync.client import ClientConnection, connect
from websockets.sync.server import ServerConnection, serve

LOG = logging.getLogger("tests.relay")
LOG.setLevel(logging.INFO)  # its debug log would print the headers it checks

_DIRECT: dict[str, Any] = (
    {"legacy": True} if int(websockets.__version__.split(".")[0]) >= 17 else {}
)
"""websockets 17.1 warns when ``connect()`` is not used as a context manager
unless ``legacy=True``; websockets 16 (what Python 3.10 gets) has no such
option and connects directly anyway."""


class Relay:
    """See the module docstring. ``upstream=None``: record only (the
    client's messages are kept, nothing is answered)."""

    def __init__(self, upstream: str | None, *, require: tuple[str, str] | None = None) -> None:
        self.upstream = upstream
        self.require = require
        self.lock = threading.Lock()
        self.requests: list[Headers] = []
        self.sent: list[str | bytes] = []
        self._links: dict[int, ClientConnection] = {}
        self._live: set[ServerConnection] = set()
        self._server = serve(
            self._handle,
            "127.0.0.1",
            0,
            process_request=self._process_request,
            select_subprotocol=self._select,
            max_size=None,
            logger=LOG,
        )
        self.port = self._server.socket.getsockname()[1]
        self.url = f"ws://127.0.0.1:{self.port}"
        self._thread = threading.Thread(target=self._server.serve_forever, daemon=True)
        self._thread.start()

    def _process_request(self, conn: ServerConnection, request: Request) -> Response | None:
        with self.lock:
            self.requests.append(request.headers)
        if self.require is not None:
            name, value = self.require
            if request.headers.get(name) != value:
                return conn.respond(HTTPStatus.UNAUTHORIZED, "token required\n")
        return None

    def _select(self, conn: ServerConnection, offered: Any) -> Any:
        """Open the upstream offering what the client offered; choose what
        the upstream chose."""
        if self.upstream is None:
            return None
        link = connect(
            self.upstream,
            subprotocols=list(offered) or None,
            max_size=None,
            logger=LOG,
            **_DIRECT,
        )
        with self.lock:
            self._links[id(conn)] = link
        return link.subprotocol

    def _handle(self, conn: ServerConnection) -> None:
        with self.lock:
            link = self._links.pop(id(conn), None)
            self._live.add(conn)
        if link is None and self.upstream is not None:  # no subprotocol offered
            link = connect(self.upstream, max_size=None, logger=LOG, **_DIRECT)

        def down() -> None:
            assert link is not None
            with contextlib.suppress(ConnectionClosed):
                for message in link:
                    conn.send(message)
            conn.close()

        thread = None
        if link is not None:
            thread = threading.Thread(target=down, daemon=True)
            thread.start()
        try:
            for message in conn:
                with self.lock:
                    self.sent.append(message)
                if link is not None:
                    link.send(message)
        except ConnectionClosed:
            pass
        finally:
            with self.lock:
                self._live.discard(conn)
            if link is not None:
                link.close()
            if thread is not None:
                thread.join(5)

    def drop(self) -> int:
        """Close every client connection open now (the upstream links
        follow); returns how many were closed."""
        with self.lock:
            live = list(self._live)
        for conn in live:
            conn.close(1001, "dropped by the relay")
        return len(live)

    def stop(self) -> None:
        self._server.shutdown()
        self._thread.join(5)

    def __enter__(self) -> Relay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
