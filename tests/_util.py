"""Small helpers shared by the tests."""

from __future__ import annotations

import socket
import time
from collections.abc import Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb


async def wait_until(predicate: Callable[[], object], timeout: float = 5.0, what: str = "") -> None:
    """Poll ``predicate`` every 10 ms until it is truthy; fail after ``timeout``."""
    with anyio.move_on_after(timeout):
        while not predicate():
            await anyio.sleep(0.01)
        return
    raise AssertionError(f"timed out after {timeout} s waiting for {what or predicate}")


async def take(sub: rmb.Subscription, n: int, timeout: float = 15.0) -> list[rmb.Message]:
    """The next ``n`` messages of ``sub``, in order; fail after ``timeout``."""
    got: list[rmb.Message] = []
    with anyio.fail_after(timeout):
        async for msg in sub:
            got.append(msg)
            if len(got) == n:
                break
    return got


ASYNCIO_LOOPS = [
    pytest.param("asyncio", id="asyncio"),
    pytest.param(("asyncio", {"use_uvloop": True}), id="uvloop"),
]
"""``anyio_backend`` values for tests of asyncio-only code: the standard
loop and uvloop (which uvicorn runs whenever it is installed), whose
transports are not ``asyncio.Transport`` subclasses."""


# A reconnect policy for tests: retries within 0.2 s.
FAST = rmb.ReconnectPolicy(initial_delay=0.05, max_delay=0.2, jitter=0.1)


async def wait_port_free(port: int, timeout: float = 5.0) -> None:
    """The SDK's stop() returns before its listener is closed."""
    deadline = time.monotonic() + timeout
    while True:
        with socket.socket() as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                s.bind(("127.0.0.1", port))
                return
            except OSError:
                if time.monotonic() > deadline:
                    raise
        await anyio.sleep(0.02)


async def routed(session: Any, key: str, timeout: float = 10.0, *, queryable: bool = False) -> None:
    """Wait until the Zenoh router routes puts on ``key`` to a subscriber
    (queries to a queryable, with ``queryable``), as a raw eclipse-zenoh
    ``session``'s publisher (querier) sees it: its matching status. A fixed
    sleep after declaring was not always enough under CI's load: a sample
    put before the route exists is lost."""
    sender = session.declare_querier(key) if queryable else session.declare_publisher(key)
    try:
        await wait_until(
            lambda: sender.matching_status.matching,
            timeout,
            what=f"the router to route {key} to a {'queryable' if queryable else 'subscriber'}",
        )
    finally:
        sender.undeclare()


def fast_options(**kw: Any) -> rmb.ClientOptions:
    """Client options for a local test server: no wait for advertisements to
    settle, a 5 s connect timeout; ``kw`` overrides."""
    kw.setdefault("advertise_settle", 0.0)
    kw.setdefault("connect_timeout", 5.0)
    return rmb.ClientOptions(**kw)


def websocket_of(robot: rmb.Client) -> Any:
    """The WebSocket of a Foxglove or rosbridge client's connection (its
    counters: reads, inline_messages, quiet_holds)."""
    return robot._conn.adapter._ws  # type: ignore[attr-defined]
