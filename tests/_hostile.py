"""Helpers shared by the ``test_hostile_*`` tests (the hostile server is
``peers.hostile``)."""

from __future__ import annotations

import asyncio
import os
from functools import partial

import anyio
import sniffio

import ros_mobile_bridge as rmb
from _util import fast_options

WIRE = {"foxglove": "foxglove-ws", "rosbridge": "rosbridge"}


options = partial(
    fast_options,
    reconnect=None,
    discovery_grace=0.05,
    teardown_timeout=1.0,
    latency_probe_interval=0,
)
"""Client options for the hostile server (either protocol): ``fast_options``
without reconnect, probes, or long waits at the start and the end."""


async def until_data(sub: rmb.Subscription, data: str, timeout: float = 10.0) -> rmb.Message:
    """The first message of ``sub`` whose ``data`` field is ``data``; for a
    count (``"1"``, ``"2"``, ... as ``stream_strings`` sends), the first at
    or past it: a client the test just loaded (a flood read) may lag, and
    its adaptive throttle then replaces a count with the next one."""
    with anyio.fail_after(timeout):
        async for msg in sub:
            got = getattr(msg.data, "data", None)
            if got == data or (
                data.isdigit() and isinstance(got, str) and got.isdigit() and int(got) >= int(data)
            ):
                return msg
    raise AssertionError(f"the subscription ended before {data!r}")


def task_count() -> int:
    """Tasks alive in the running event loop (asyncio or trio)."""
    if sniffio.current_async_library() == "asyncio":
        return len(asyncio.all_tasks())
    import trio

    def count(task: trio.lowlevel.Task) -> int:
        return 1 + sum(count(t) for n in task.child_nurseries for t in n.child_tasks)

    return count(trio.lowlevel.current_root_task())


def fd_count() -> int:
    return len(os.listdir("/proc/self/fd"))


def rss_bytes() -> int:
    """Resident set size of this process."""
    with open("/proc/self/status", encoding="ascii") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) * 1024
    raise RuntimeError("no VmRSS in /proc/self/status")
