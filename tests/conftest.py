"""Every async test runs on asyncio and on trio (anyio's pytest plugin in
auto mode, pyproject.toml, with the ``anyio_backend`` fixture below), except
the protocol tests of :data:`LOOP_NEUTRAL`, which run once each.

Collection also marks what each test needs: ``ros`` (the ROS 2 peer
environment, CPython 3.11 wheels only) and ``peer`` (any server: a real
peer or a scripted one), so ``-m "not peer"`` is the quick run
(``scripts/test --quick``); the ``ros`` tests share one pytest-xdist
worker (one ROS graph and bridge per run)."""

from __future__ import annotations

import functools
import json
import os
import random
import warnings
import zlib
from collections.abc import Iterator
from types import ModuleType
from typing import TYPE_CHECKING, Any

import pytest
from hypothesis import settings
from hypothesis import strategies as st
from hypothesis.errors import HypothesisSideeffectWarning

from _util import SHORT_SEARCHES, examples
from _util import UVLOOP as _UVLOOP
from peers.zenoh_router import ZenohRouter

if TYPE_CHECKING:
    from peers.foxglove_sdk import SdkServer
    from ros_mobile_bridge.demo import DemoRobot

_ROS_FIXTURES = frozenset({"ros_peer_env", "ros_graph", "rosbridge", "rosbridge_factory"})
"""The fixtures of tests/peers/ros_fixtures.py: the ROS 2 Jazzy peer environment."""

_PEER_FIXTURES = _ROS_FIXTURES | {"ros_share", "sdk", "zenoh_router", "raw", "server", "robot"}
"""Fixtures that start a server (a test module's ``robot`` is a demo robot)."""

LOOP_NEUTRAL = frozenset(
    {
        "test_bytes_received_peers",
        "test_connection_options",
        "test_demo_robot",
        "test_error_contract",
        "test_foxglove_legacy",
        "test_foxglove_sdk",
        "test_parameter_events",
        "test_publish_checks",
        "test_raw_subscribe",
        "test_record",
        "test_rosbridge",
        "test_rosbridge_params_watch",
        "test_rosbridge_peer",
        "test_serve",
        "test_zenoh_actions",
        "test_zenoh_describe",
        "test_zenoh_params_watch",
        "test_zenoh_queryable",
        "test_zenoh_record",
        "test_zenoh_sdk",
        "test_zenoh_serve",
    }
)
"""Test modules of protocol behaviour against peers, whose code under the
client is the same on every event loop: the loop-specific paths below them
(the WebSocket and asyncio streams, trio's reads and timers, the Zenoh
session's hand-over to the loop, the subscription queue's wake-ups, the lag
monitor, signals, the sync worker) have tests of their own that run on both
loops (test_asyncio_stream, test_websocket_*, test_read_*, test_transport*,
test_zenoh, test_flow, test_wakeup, test_trio_timers, test_lag, ...). Each
test of these modules runs on one loop, picked from its name, so each module
runs about half its tests on each loop. ``RMB_BOTH_LOOPS=1`` runs them on
both."""


UVLOOP_TOO = frozenset(
    {
        "test_lag",
        "test_read_coalesce",
        "test_read_hold",
        "test_reconnect",
        "test_signals",
        "test_throttle_real",
        "test_transport",
        "test_transport_faults",
        "test_wakeup",
        "test_websocket_inline",
        "test_zenoh",
    }
)
"""Test modules of the loop-specific paths whose async tests run on asyncio
on uvloop too (the ``uvloop`` parameter of ``anyio_backend``): the
transports and their read pacing, the wake-ups and timers, the lag monitor,
reconnection, the Zenoh session's hand-over to the loop. uvloop's transports,
timers and thread-safe calls are its own code, not asyncio's. Modules with
a loop parameter of their own add uvloop there (test_asyncio_stream, the
sync worker's in test_sync, the ``rmb`` processes' in test_signals,
test_uvloop); the others run on asyncio and trio."""


def _loops_of_its_own(item: pytest.Item) -> bool:
    """The test parametrizes ``anyio_backend`` itself (``ASYNCIO_LOOPS``)."""
    for mark in item.iter_markers("parametrize"):
        names = mark.args[0] if mark.args else mark.kwargs.get("argnames", ())
        if isinstance(names, str):
            names = [n.strip() for n in names.split(",")]
        if "anyio_backend" in names:
            return True
    return False


def _has_uvloop() -> bool:
    try:
        import uvloop  # noqa: F401
    except ImportError:  # (no Windows build)
        return False
    return True


# The properties that set no example count of their own take hypothesis's
# default (100) on the main Python and a short search on the others
# (tests/_util.py's SHORT_SEARCHES says why); those that set one use
# ``examples(n)``.
settings.register_profile("short-searches", max_examples=examples(100))
if SHORT_SEARCHES:
    settings.load_profile("short-searches")


def pytest_configure(config: pytest.Config) -> None:
    """On the pytest-xdist controller, before the workers start: hypothesis's
    table of the characters ``st.text()`` draws from (every code point UTF-8
    can encode; seconds of CPU) is computed once and written to
    ``.hypothesis/`` for the workers to read, instead of computed by each
    worker at once in a fresh clone. (Hypothesis warns of slow work while
    plugins load: here it is the point.)"""
    if config.getoption("numprocesses", None) and not hasattr(config, "workerinput"):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HypothesisSideeffectWarning)
            st.characters(codec="utf-8").validate()


def _one_loop(item: pytest.Item) -> str:
    """The loop a loop-neutral test runs on: stable for the test, half and half."""
    params = getattr(getattr(item, "callspec", None), "params", {})
    key = repr(
        (
            item.module.__name__,
            getattr(item, "originalname", item.name),
            sorted(
                (name, repr(value)) for name, value in params.items() if name != "anyio_backend"
            ),
        )
    )
    return ("asyncio", "trio")[zlib.crc32(key.encode()) % 2]


@functools.cache
def _starts_servers(module: ModuleType) -> bool:
    """The module imports a server: the peers package (real peers, the
    scripted and hostile servers) or the demo robot."""
    return any(
        (getattr(value, "__module__", None) or getattr(value, "__name__", "")).startswith(
            ("peers", "ros_mobile_bridge.demo")
        )
        for value in vars(module).values()
        if isinstance(value, type | ModuleType) or callable(value)
    )


@pytest.hookimpl(tryfirst=True)  # before pytest-xdist reads the xdist_group marks
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark ``ros`` and ``peer`` tests (see the module docstring), keep the
    ``ros`` ones on one xdist worker, and run each loop-neutral test on its
    one loop."""
    both = os.environ.get("RMB_BOTH_LOOPS", "") not in ("", "0")
    uvloop = _has_uvloop()
    kept: list[pytest.Item] = []
    dropped: list[pytest.Item] = []
    for item in items:
        fixtures = set(getattr(item, "fixturenames", ()))
        if _ROS_FIXTURES & fixtures:
            item.add_marker(pytest.mark.ros)
            item.add_marker(pytest.mark.xdist_group("ros"))
        module = getattr(item, "module", None)
        if _PEER_FIXTURES & fixtures or (module is not None and _starts_servers(module)):
            item.add_marker(pytest.mark.peer)
        backend = getattr(getattr(item, "callspec", None), "params", {}).get("anyio_backend")
        if (
            backend == _UVLOOP.values[0]
            and not _loops_of_its_own(item)
            and (module is None or module.__name__ not in UVLOOP_TOO or not uvloop)
        ):
            dropped.append(item)
            continue
        if (
            not both
            and isinstance(backend, str)
            and module is not None
            and module.__name__ in LOOP_NEUTRAL
            and backend != _one_loop(item)
        ):
            dropped.append(item)
            continue
        kept.append(item)
    if dropped:
        config.hook.pytest_deselected(items=dropped)
        items[:] = kept


@pytest.fixture(params=["asyncio", "trio", _UVLOOP])
def anyio_backend(request: pytest.FixtureRequest) -> object:
    """asyncio and trio; asyncio on uvloop too in the modules of
    :data:`UVLOOP_TOO` (collection drops the others' ``uvloop`` items)."""
    return request.param


@pytest.fixture(scope="session")
def _shared_zenoh_router() -> Iterator[ZenohRouter]:
    pytest.importorskip("zenoh")
    with ZenohRouter() as router:
        yield router


@pytest.fixture
def zenoh_router(_shared_zenoh_router: ZenohRouter) -> ZenohRouter:
    """The eclipse-zenoh router of this test process (one per pytest-xdist
    worker; tests/peers/zenoh_router.py) on a loopback port. Tests sharing it
    do not see each other: each has its own ROS domain (``zenoh_domain``) and
    closes its sessions. A test that stops or restarts a router starts its
    own ``ZenohRouter``."""
    if not _shared_zenoh_router.running:  # (stopped by a test that should not have)
        _shared_zenoh_router.start()
    return _shared_zenoh_router


@pytest.fixture
def raw(zenoh_router: ZenohRouter) -> Iterator[Any]:
    """A bare eclipse-zenoh client session to the test's router: the fault
    injector and the raw caller of the Zenoh tests."""
    zenoh = pytest.importorskip("zenoh")
    config = zenoh.Config()
    config.insert_json5("mode", '"client"')
    config.insert_json5("connect/endpoints", json.dumps([zenoh_router.locator]))
    config.insert_json5("scouting/multicast/enabled", "false")
    session = zenoh.open(config)
    try:
        yield session
    finally:
        session.close()


@pytest.fixture
def server() -> Iterator[SdkServer]:
    """A fresh Foxglove SDK server on a loopback port (tests/peers/foxglove_sdk.py);
    a module that needs one set up otherwise defines its own ``server``."""
    from peers.foxglove_sdk import SdkServer

    with SdkServer() as srv:
        yield srv


@pytest.fixture(scope="module")
def robot() -> Iterator[DemoRobot]:
    """The embedded demo robot (``ros_mobile_bridge.demo``, the official
    Foxglove SDK server) with its default rates, one per module; a module
    that needs another (other rates, a fresh one per test) defines its own
    ``robot``."""
    from ros_mobile_bridge.demo import DemoRobot

    with DemoRobot() as bot:
        yield bot


@pytest.fixture
def zenoh_domain() -> int:
    """A random ROS domain id, so tests (and parallel runs) do not see each other."""
    return random.SystemRandom().randint(1, 200)
