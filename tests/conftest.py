"""Every async test runs on asyncio and on trio: anyio's pytest plugin in auto
mode (pyproject.toml) with this backend fixture."""

from __future__ import annotations

import random
from collections.abc import Iterator

import pytest

from peers.zenoh_router import ZenohRouter


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
def zenoh_domain() -> int:
    """A random ROS domain id, so tests (and parallel runs) do not see each other."""
    return random.SystemRandom().randint(1, 200)
