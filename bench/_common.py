"""Small helpers every benchmark here shares."""

from __future__ import annotations

import importlib.metadata
import platform
from collections.abc import Awaitable, Callable, Mapping, Sequence
from contextlib import suppress
from typing import Any, TypeVar

import anyio

import ros_mobile_bridge as rmb
from ros_mobile_bridge._loop._backends import BACKENDS, run_args

__all__ = [
    "DROP_REASONS",
    "LOOPS",
    "check_fates",
    "client_internals",
    "run_on",
    "subscription_counts",
    "versions",
]

DROP_REASONS = (
    "dropped_throttle",
    "dropped_conflated",
    "dropped_overflow",
    "dropped_breaker",
    "dropped_replay",
)
"""Every way a received frame can leave a subscription without being delivered
(a version without one of them counts 0 for it)."""


T = TypeVar("T")

LOOPS = BACKENDS
"""The event loops a benchmark runs on: ``uvloop`` is asyncio on uvloop."""


def run_on(loop: str, fn: Callable[..., Awaitable[T]], *args: Any) -> T:
    """``anyio.run(fn, *args)`` on ``loop`` (one of :data:`LOOPS`), mapped
    as the library maps the loops it starts (``_loop._backends.run_args``)."""
    backend, options = run_args(loop, None, f"--backend {loop}")
    return anyio.run(fn, *args, backend=backend, backend_options=options)


def versions(names: Sequence[str]) -> str:
    """The Python version and the installed versions of ``names``."""
    found = []
    for name in names:
        with suppress(importlib.metadata.PackageNotFoundError):
            found.append(f"{name} {importlib.metadata.version(name)}")
    return f"python {platform.python_version()}, " + ", ".join(found)


def subscription_counts(sub: rmb.Subscription) -> dict[str, int]:
    """The fate of every frame a subscription received, for a benchmark's
    JSON: delivered, each drop reason, still queued; plus decode failures
    (delivered raw)."""
    stats = sub.stats
    counts = {"received": stats.received, "delivered": stats.delivered}
    counts.update({reason: getattr(stats, reason, 0) for reason in DROP_REASONS})
    counts["queued"] = len(sub._queue)
    counts["decode_failures"] = stats.decode_failures
    return counts


def check_fates(
    counts: Mapping[str, int], *, sent: int | None = None, may_drop: Sequence[str] = ()
) -> list[str]:
    """What is wrong with one run's :func:`subscription_counts`: frames that
    vanished inside the library (received but neither delivered, dropped
    for a counted reason nor still queued), drops for a reason the case does
    not allow (``may_drop``), and, given ``sent``, frames the client never
    received or delivered although nothing was allowed to drop them."""
    problems = []
    accounted = counts["delivered"] + counts["queued"] + sum(counts[r] for r in DROP_REASONS)
    if accounted != counts["received"]:
        problems.append(
            f"{counts['received'] - accounted} frames vanished"
            f" (received {counts['received']}, accounted for {accounted})"
        )
    for reason in DROP_REASONS:
        if counts[reason] and reason not in may_drop:
            problems.append(f"{counts[reason]} frames {reason.replace('_', ' ')}")
    if sent is not None and not may_drop and counts["delivered"] + counts["queued"] < sent:
        problems.append(
            f"only {counts['delivered']} of {sent} frames delivered ({counts['queued']} queued)"
        )
    return problems


def client_internals(robot: rmb.Client) -> tuple[Any, Any]:
    """A client's adapter and outbox, for a benchmark's instrumentation
    (private; None where the layout changed): through its connection since
    the connection moved out of Client, else the attributes Client held
    before, so one bench script measures both. (An empty outbox is falsy:
    compared with None, not by truth.)"""
    conn: Any = getattr(robot, "_conn", None)
    if conn is not None:
        outbound = getattr(conn, "outbound", None)
        return getattr(conn, "adapter", None), getattr(outbound, "outbox", None)
    return getattr(robot, "_backend", None), getattr(robot, "_outbox", None)
