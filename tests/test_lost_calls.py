"""A call cut off by a lost connection names the cause, on every transport.

A service call, an action goal or a parameter operation in flight when the
peer dies raises :class:`rmb.NotConnected` saying the connection was lost,
at the loss: not a timeout, not a server error, and not after the
reconnection. Each test kills the real peer while the request is held at
the server (a handler that never answers), with a 60 s timeout on the call
that must not be what ends it."""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import FAST, wait_until
from _util import zenoh_options as zoptions

pytest_plugins = ["peers.ros_fixtures"]

CALL_TIMEOUT = 60.0
"""The calls' own timeout: far past the loss, so it cannot be what ends them."""
PROMPT = 20.0
"""The test's bound on the wait for the call to end (a third of the call's timeout)."""
LOST = "connection was lost"

POLICIES = {"no-reconnect": None, "reconnect": FAST}


async def cut_off(
    start: Callable[[], Awaitable[Any]], held: Callable[[], bool], kill: Callable[[], Any]
) -> BaseException:
    """Run ``start`` (the request), wait until ``held`` (the peer holds it),
    ``kill`` the peer; return what the request raised, within
    :data:`PROMPT` seconds."""
    outcome: list[BaseException] = []

    async def request() -> None:
        try:
            await start()
        except Exception as exc:
            outcome.append(exc)
        else:  # pragma: no cover - the assertion below says it
            outcome.append(AssertionError("the request succeeded"))

    async with anyio.create_task_group() as tg:
        tg.start_soon(request)
        await wait_until(held, timeout=15.0, what="the request held at the peer")
        await anyio.to_thread.run_sync(kill)
        with anyio.fail_after(PROMPT):
            await wait_until(lambda: bool(outcome), timeout=PROMPT, what="the request to end")
    return outcome[0]


def assert_lost(error: BaseException) -> None:
    assert isinstance(error, rmb.NotConnected), repr(error)
    assert LOST in str(error), str(error)


# -- zenoh ------------------------------------------------------------------------------------
@pytest.mark.parametrize("policy", sorted(POLICIES))
async def test_zenoh_a_call_cut_off_by_the_router_death_raises_not_connected(
    sdk: Callable[..., Any], zenoh_domain: int, policy: str
) -> None:
    from peers.zenoh_router import ZenohRouter

    with ZenohRouter() as router:
        server = sdk("service", "--name", "/held", "--hang", router=router)
        opts = zoptions(
            zenoh_domain,
            connect_timeout=2.0,
            keepalive_interval=0.2,
            keepalive_timeout=1.0,
            reconnect=POLICIES[policy],
        )
        async with rmb.connect(router.locator, options=opts) as client:
            await wait_until(
                lambda: any(s.name == "/held" for s in client.services),
                timeout=15.0,
                what="the service",
            )
            error = await cut_off(
                lambda: client.call_service("/held", {"data": True}, timeout=CALL_TIMEOUT),
                lambda: bool(server.records()),
                router.kill,
            )
    assert_lost(error)
