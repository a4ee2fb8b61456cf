"""What several ``rmb`` verbs share: opening the robot, graph names as
ros2 reads them, type names compared in either spelling, output lines, and
the notice about a topic that has not appeared."""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Iterable
from contextlib import AbstractAsyncContextManager
from typing import Any

import anyio

from .. import _connect
from .._checks import nearest as nearest  # one nearest-names rule, the library's
from .._core._client import Client
from .._options import ClientOptions

__all__ = [
    "NOTICE_AFTER_S",
    "check_type",
    "graph_name",
    "nearest",
    "notice_if_missing",
    "open_robot",
    "out",
    "same_type",
    "warn",
]

NOTICE_AFTER_S = 3.0
"""Seconds without a message before ``echo``/``hz``/``bw`` say on stderr
that the topic has not appeared."""


ZENOH_CONFIG_ENV = "ZENOH_SESSION_CONFIG_URI"
"""The Zenoh session configuration file rmw_zenoh reads; ``rmb`` reads it
too (``ClientOptions.zenoh_config``), for a ``tls/`` router's CA, a client
certificate or a user and password."""


def open_robot(ns: argparse.Namespace, **options: Any) -> AbstractAsyncContextManager[Client]:
    """``connect()`` to the robot the command line names (over Zenoh,
    starting from ``$ZENOH_SESSION_CONFIG_URI`` when it is set)."""
    config = os.environ.get(ZENOH_CONFIG_ENV, "").strip()
    if config:
        options.setdefault("zenoh_config", config)
    return _connect.connect(
        ns.url, protocol=ns.protocol, options=ClientOptions(connect_timeout=ns.timeout, **options)
    )


def graph_name(text: str, kind: str = "name") -> str:
    """A topic, service, action or node name as ``ros2`` reads it from the
    command line: a relative name (``odom``) is resolved against ``/``
    (``/odom``), as for a node in the root namespace; an absolute one is
    kept. Every verb's graph-name argument goes through here.
    :class:`UsageError` for an empty name, one with spaces, or a private
    (``~``) name, which needs a node."""
    from ._format import UsageError

    name = text.strip()
    if not name or any(c.isspace() for c in name):
        raise UsageError(f"{kind} {text!r} is not a ROS name")
    if name.startswith("~"):
        raise UsageError(f"{kind} {text!r} is private to a node: give its full name (/node/...)")
    return name if name.startswith("/") else "/" + name


def same_type(given: str, known: str) -> bool:
    """Whether two spellings name one type: ``pkg/msg/T`` and ``pkg/T``
    are the same (the short form leaves the kind out)."""
    if given == known:
        return True
    a, b = given.split("/"), known.split("/")
    if len(a) == len(b):
        return False
    return (a[0], a[-1]) == (b[0], b[-1])


def check_type(kind: str, name: str, given: str, known: str | None) -> None:
    """Refuse (:class:`UsageError`) a type the user gave that is not the one
    the robot lists for ``name`` (ros2's ``echo /odom nav_msgs/msg/Odometry``
    and ``service call /x pkg/srv/T`` forms); nothing to check when the robot
    does not say (``known`` None or empty)."""
    from ._format import UsageError

    if given.count("/") not in (1, 2) or any(c.isspace() for c in given):
        raise UsageError(f"{given!r} is not a ROS type (pkg/{kind}/Type)")
    if known and not same_type(given, known):
        raise UsageError(f"{name} is a {known}, not a {given}")


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
