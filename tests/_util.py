"""Small helpers shared by the tests."""

from __future__ import annotations

import os
import socket
import time
from collections.abc import Callable
from typing import Any, TypeVar

import anyio
import pytest

import ros_mobile_bridge as rmb

T = TypeVar("T")

SHORT_SEARCHES = os.environ.get("RMB_SHORT_SEARCHES", "") not in ("", "0")
"""Set by scripts/test for its runs on the other Pythons (3.10, 3.13): there
the random searches (the hypothesis properties, the fuzz harnesses' smoke
runs) take a short budget, :func:`examples`; the main Python's run takes the
full one. Why: what may differ from one Python to another under the same
code is the interpreter and the standard library (int and str limits,
``json``, ``struct``, ``memoryview``, ``typing``), which a search meets within
its first examples (hypothesis draws empty, zero, extreme and the package's
own constant values with raised probability from the first example on). The
rest of a search looks for rarer inputs, which do not depend on the Python:
the main run searches them in full, with fresh random examples, every run."""


def examples(full: int) -> int:
    """The budget of a random search (hypothesis examples, fuzz sessions)
    whose full budget is ``full``: ``full`` on the main Python; a fifth of it,
    at least 10, with :data:`SHORT_SEARCHES` (the two other Pythons then cost
    two fifths of one full search, not two full searches)."""
    return max(10, full // 5) if SHORT_SEARCHES else full


def _timed_out(
    timeout: float, what: str | Callable[[], object], predicate: object
) -> AssertionError:
    described = what() if callable(what) else what
    return AssertionError(f"timed out after {timeout} s waiting for {described or predicate}")


async def wait_until(
    predicate: Callable[[], T],
    timeout: float = 5.0,
    what: str | Callable[[], object] = "",
    *,
    interval: float = 0.01,
) -> T:
    """Poll ``predicate`` every ``interval`` seconds until it returns something
    truthy, and return that; after ``timeout`` seconds fail with an
    ``AssertionError`` naming ``what`` (a callable ``what`` is called then, to
    report the state at the timeout). An exception of ``predicate`` propagates
    at once. ``wait_until_sync`` is the same for sync tests."""
    with anyio.move_on_after(timeout):
        while not (result := predicate()):
            await anyio.sleep(interval)
        return result
    raise _timed_out(timeout, what, predicate)


def wait_until_sync(
    predicate: Callable[[], T],
    timeout: float = 5.0,
    what: str | Callable[[], object] = "",
    *,
    interval: float = 0.01,
) -> T:
    """``wait_until`` for sync tests (blocks the thread): the truthy value of
    ``predicate``, or an ``AssertionError`` naming ``what`` after ``timeout``.
    Never returns on a timeout."""
    deadline = time.monotonic() + timeout
    while not (result := predicate()):
        if time.monotonic() >= deadline:
            raise _timed_out(timeout, what, predicate)
        time.sleep(interval)
    return result


async def take(sub: rmb.Subscription, n: int, timeout: float = 15.0) -> list[rmb.Message]:
    """The next ``n`` messages of ``sub``, in order; fail after ``timeout``
    saying how many came (and the subscription's counters)."""
    got: list[rmb.Message] = []
    with anyio.move_on_after(timeout) as scope:
        async for msg in sub:
            got.append(msg)
            if len(got) == n:
                break
    if scope.cancelled_caught:
        last = got[-1].data if got else None
        raise TimeoutError(
            f"{len(got)} of {n} messages on {sub.topic} within {timeout:g} s (the last: "
            f"{last!r}); {sub.stats}"
        )
    return got


UVLOOP = pytest.param(("asyncio", {"use_uvloop": True}), id="uvloop")
"""The ``anyio_backend`` value of asyncio on uvloop."""

ASYNCIO_LOOPS = [pytest.param("asyncio", id="asyncio"), UVLOOP]
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


async def unrouted(
    session: Any, key: str, timeout: float = 10.0, *, queryable: bool = False
) -> None:
    """Wait until the Zenoh router no longer routes puts on ``key`` to any
    subscriber (queries to any queryable, with ``queryable``), as a raw
    eclipse-zenoh ``session``'s publisher (querier) sees it: an undeclared
    subscriber's route lingers a while, and a later :func:`routed` would see
    it instead of a new one's."""
    sender = session.declare_querier(key) if queryable else session.declare_publisher(key)
    try:
        await wait_until(
            lambda: not sender.matching_status.matching,
            timeout,
            what=f"the router to drop its route of {key}",
        )
    finally:
        sender.undeclare()


def fast_options(**kw: Any) -> rmb.ClientOptions:
    """Client options for a local test server (the Foxglove SDK server, the
    demo robot, the hostile server): no wait for advertisements to settle,
    a 5 s connect timeout; ``kw`` overrides."""
    kw.setdefault("advertise_settle", 0.0)
    kw.setdefault("connect_timeout", 5.0)
    return rmb.ClientOptions(**kw)


def rosbridge_options(**kw: Any) -> rmb.ClientOptions:
    """Client options for rosbridge_server_rs on the test ROS graph: the
    graph polled every 0.25 s, a 10 s connect timeout, 3 s for the
    teardown, no reconnect (a test that wants one passes it); ``kw``
    overrides."""
    kw.setdefault("connect_timeout", 10.0)
    kw.setdefault("discovery_interval", 0.25)
    kw.setdefault("teardown_timeout", 3.0)
    kw.setdefault("reconnect", None)
    return rmb.ClientOptions(**kw)


def zenoh_options(domain: int, **kw: Any) -> rmb.ClientOptions:
    """Client options for a Zenoh router: the test's ROS ``domain`` (the
    ``zenoh_domain`` fixture), the library's defaults otherwise; ``kw``
    overrides."""
    return rmb.ClientOptions(domain_id=domain, **kw)


def websocket_of(robot: rmb.Client) -> Any:
    """The WebSocket of a Foxglove or rosbridge client's connection (its
    counters: reads, inline_messages, quiet_holds)."""
    return robot._conn.adapter._ws  # type: ignore[attr-defined]
