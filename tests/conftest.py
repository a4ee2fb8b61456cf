"""Every async test runs on asyncio and on trio: anyio's pytest plugin in auto
mode (pyproject.toml) with this backend fixture."""

from __future__ import annotations

import pytest


@pytest.fixture(params=["asyncio", "trio"])
def anyio_backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)
