"""What several ``rmb`` verbs share: opening the robot, output lines, and
the notice about a topic that has not appeared."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterable
from contextlib import AbstractAsyncContextManager
from typing import Any

import anyio

from .. import _connect
from .._checks import nearest as nearest  # one nearest-names rule, the library's
from .._client import Client
from .._options import ClientOptions

__all__ = ["NOTICE_AFTER_S", "nearest", "notice_if_missing", "open_robot", "out", "warn"]

NOTICE_AFTER_S = 3.0
"""Seconds without a message before ``echo``/``hz``/``bw`` say on stderr
that the topic has not appeared."""


def open_robot(ns: argparse.Namespace, **options: Any) -> AbstractAsyncContextManager[Client]:
    """``connect()`` to the robot the command line names."""
    return _connect.connect(
        ns.url, protocol=ns.protocol, options=ClientOptions(connect_timeout=ns.timeout, **options)
    )


def out(text: str) -> None:
    """One line on stdout, flushed (a closed pipe raises here, at once)."""
    print(text, flush=True)


def warn(text: str) -> None:
    """One line on stderr."""
    print(f"rmb: {text}", file=sys.stderr, flush=True)


def missing_line(kind: str, name: str, known: Iterable[str]) -> str:
    """``'/odm' is not a topic the robot offers; nearest: /odom``."""
    names = sorted(set(known))
    close = nearest(name, names)
    if close:
        hint = f"nearest: {', '.join(close)}"
    elif names:
        more = f", ... ({len(names)} in all)" if len(names) > 8 else ""
        hint = f"known: {', '.join(names[:8])}{more}"
    else:
        hint = f"the robot offers no {kind}s"
    return f"{name!r} is not a {kind} the robot offers; {hint}"


async def notice_if_missing(robot: Client, topic: str, seen: list[int]) -> None:
    """After :data:`NOTICE_AFTER_S` without a message (``seen[0] == 0``),
    say on stderr that ``topic`` has not appeared (when the robot does not
    list it), with the nearest names it does list. The caller keeps
    waiting: the topic may still come."""
    await anyio.sleep(NOTICE_AFTER_S)
    if seen[0]:
        return
    names = [t.name for t in robot.topics]
    if topic in names:
        warn(f"{topic} is listed, but no message came in {NOTICE_AFTER_S:g} s; still waiting")
        return
    warn(
        f"{topic} has not appeared after {NOTICE_AFTER_S:g} s (still waiting): "
        + missing_line("topic", topic, names)
    )
