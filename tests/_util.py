"""Small helpers shared by the tests."""

from __future__ import annotations

from collections.abc import Callable

import anyio

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
