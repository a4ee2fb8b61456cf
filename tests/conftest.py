"""Every async test runs on asyncio and on trio: anyio's pytest plugin in auto
mode (pyproject.toml) with this backend fixture."""

from __future__ import annotations

import json
import random
from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

import pytest

from peers.zenoh_router import ZenohRouter

if TYPE_CHECKING:
    from peers.foxglove_sdk import SdkServer
    from ros_mobile_bridge.demo import DemoRobot

_ROS_FIXTURES = frozenset({"ros_peer_env", "ros_graph", "rosbridge", "rosbridge_factory"})
"""The fixtures of tests/peers/ros_fixtures.py: the ROS 2 Jazzy peer environment."""


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Mark every test that needs the ROS 2 peer environment (its wheels are
    for CPython 3.11 only) as ``ros``: the other Python versions run
    ``-m "not ros"`` (scripts/test)."""
    for item in items:
        if _ROS_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.ros)


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


@pytest.fixture
def zenoh_router() -> Iterator[ZenohRouter]:
    """A fresh eclipse-zenoh router on a loopback port (tests/peers/zenoh_router.py)."""
    pytest.importorskip("zenoh")
    with ZenohRouter() as router:
        yield router


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
