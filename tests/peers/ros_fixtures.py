"""pytest fixtures for tests against a real ROS 2 graph behind rosbridge_server_rs.

A test module loads them with::

    pytest_plugins = ["peers.ros_fixtures"]

(a plugin, not ``import *``: its collection hook builds the peer environment
before any test runs, so the build, minutes on a cold cache, is not cut by
pytest-timeout's per-test limit, which covers fixture setup).

Fixtures (all session-scoped except ``rosbridge_factory``):

- ``ros_peer_env``: the :class:`~peers.ros_env.PeerEnv`;
- ``ros_graph``: the running :class:`~peers.rosbridge.RosGraph` (random domain);
- ``rosbridge``: a :class:`~peers.rosbridge.RosBridge` with default flags,
  ready (the graph discovered);
- ``rosbridge_factory``: ``start(*flags) -> RosBridge``, another bridge on the
  same graph with extra flags, stopped after the test;
- ``ros_share``: the official interface files (``share/<pkg>/<kind>/``), laid
  out as zenoh-ros2-sdk nodes look for them;
- ``sdk``: ``start(role, *args, domain=None, router=None) -> SdkNode``, a
  zenoh-ros2-sdk node on the test's zenoh router and domain (the
  ``zenoh_router`` and ``zenoh_domain`` fixtures of ``conftest.py``), every
  one stopped after the test.

They never skip: a failed build or start fails the test with the log's tail.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import pytest

from peers.ros_env import PeerEnv, ensure_peer_env
from peers.rosbridge import RosBridge, RosGraph
from peers.zenoh_sdk_node import SdkNode

_FIXTURES = {"ros_peer_env", "ros_graph", "rosbridge", "rosbridge_factory", "ros_share", "sdk"}
_built: PeerEnv | None = None
_build_error: BaseException | None = None


def _try_build() -> None:
    """Build (or find) the peer environment once; keep a failure for the
    tests that need it."""
    global _built, _build_error
    if _built is None and _build_error is None:
        try:
            _built = ensure_peer_env()
        except Exception as exc:
            _build_error = exc


def pytest_collection_finish(session: pytest.Session) -> None:
    """Build the peer environment once collection shows a test that needs it,
    before any test runs (so outside any test's timeout)."""
    if session.config.option.collectonly:
        return
    if any(_FIXTURES & set(getattr(item, "fixturenames", ())) for item in session.items):
        _try_build()


@pytest.fixture(scope="session")
def ros_peer_env() -> PeerEnv:
    _try_build()
    if _built is None:
        pytest.fail(f"could not build the ROS 2 peer environment:\n{_build_error}", pytrace=False)
    return _built


@pytest.fixture(scope="session")
def ros_graph(ros_peer_env: PeerEnv) -> Iterator[RosGraph]:
    graph = RosGraph.start(ros_peer_env)
    try:
        yield graph
    finally:
        graph.stop()


@pytest.fixture(scope="session")
def rosbridge(ros_peer_env: PeerEnv, ros_graph: RosGraph) -> Iterator[RosBridge]:
    bridge = RosBridge.start(ros_peer_env, ros_graph.domain_id)
    try:
        yield bridge
    finally:
        bridge.stop()


@pytest.fixture
def rosbridge_factory(
    ros_peer_env: PeerEnv, ros_graph: RosGraph
) -> Iterator[Callable[..., RosBridge]]:
    started: list[RosBridge] = []

    def start(*flags: str, **kwargs: Any) -> RosBridge:
        """Another bridge on the session graph, e.g. ``start("--fragment-timeout",
        "2")``; keyword arguments go to :meth:`RosBridge.start`."""
        bridge = RosBridge.start(ros_peer_env, ros_graph.domain_id, *flags, **kwargs)
        started.append(bridge)
        return bridge

    try:
        yield start
    finally:
        for bridge in started:
            bridge.stop()


@pytest.fixture(scope="session")
def ros_share(ros_peer_env: PeerEnv) -> Path:
    return ros_peer_env.prefix / "share"


@pytest.fixture
def sdk(zenoh_router: Any, zenoh_domain: int, ros_share: Path) -> Iterator[Callable[..., SdkNode]]:
    nodes: list[SdkNode] = []

    def start(
        role: str,
        *args: str,
        domain: int | None = None,
        router: Any = None,
        share: Path | None = None,
    ) -> SdkNode:
        """One sdk node in the given role (see tests/peers/zenoh_sdk_node.py),
        reading its definitions from ``share`` (default: the peer env's)."""
        node = SdkNode(
            (router or zenoh_router).locator,
            zenoh_domain if domain is None else domain,
            share or ros_share,
            role,
            *args,
        )
        nodes.append(node)
        return node

    try:
        yield start
    finally:
        for node in nodes:
            node.stop()
