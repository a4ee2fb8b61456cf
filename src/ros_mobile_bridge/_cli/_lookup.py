"""``rmb topic type|find`` and ``rmb service type|find``, as ``ros2 topic
type|find`` and ``ros2 service type|find``: a name's type, the names of a
type, from the robot's listing (given a second of discovery). A type matches
in either spelling (``pkg/msg/T`` or ``pkg/T``). ``--json``: ``{"name",
"type"}`` per line."""

from __future__ import annotations

import argparse
from collections.abc import Sequence

from .._core._client import Client
from ._common import missing_line, open_robot, out, same_type, warn
from ._format import json_line
from ._verb import Verb

__all__ = ["VERBS"]

_DISCOVERY_S = 1.0
"""How long ``type`` waits for a name the robot does not list yet."""


async def _listing(robot: Client, kind: str, name: str | None) -> list[tuple[str, str]]:
    """``(name, type)`` of the robot's topics or services; when ``name`` is
    given and not listed yet, discovery gets :data:`_DISCOVERY_S`."""
    import anyio

    def now() -> list[tuple[str, str]]:
        if kind == "topic":
            return sorted((t.name, t.schema_name) for t in robot.topics)
        return sorted((s.name, s.type) for s in robot.services)

    if name is not None and all(n != name for n, _ in now()):
        watch = robot.watch_topics() if kind == "topic" else robot.watch_services()
        with anyio.move_on_after(_DISCOVERY_S):
            async for items in watch:
                if any(i.name == name for i in items):
                    break
    return now()


def _print(pairs: Sequence[tuple[str, str]], as_json: bool, *, names: bool) -> None:
    for name, typ in pairs:
        if as_json:
            out(json_line({"name": name, "type": typ}))
        else:
            out(name if names else typ)


async def _type(ns: argparse.Namespace, kind: str, name: str) -> int:
    async with open_robot(ns) as robot:
        pairs = await _listing(robot, kind, name)
    found = [(n, t) for n, t in pairs if n == name]
    if not found:
        warn(missing_line(kind, name, [n for n, _ in pairs]))
        return 1
    _print(found, ns.json, names=False)
    return 0


async def _find(ns: argparse.Namespace, kind: str) -> int:
    async with open_robot(ns) as robot:
        pairs = await _listing(robot, kind, None)
    _print([(n, t) for n, t in pairs if same_type(ns.type, t)], ns.json, names=True)
    return 0  # as ros2: no match is an empty list, not a failure


async def _topic_type(ns: argparse.Namespace) -> int:
    return await _type(ns, "topic", ns.topic)


async def _topic_find(ns: argparse.Namespace) -> int:
    return await _find(ns, "topic")


async def _service_type(ns: argparse.Namespace) -> int:
    return await _type(ns, "service", ns.service)


async def _service_find(ns: argparse.Namespace) -> int:
    return await _find(ns, "service")


def _build(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help='one {"name", "type"} object per line')


VERBS = [
    Verb(("topic", "type"), "print a topic's type", ("TOPIC",), _build, _topic_type),
    Verb(
        ("topic", "find"),
        "list the topics of a type",
        ("TYPE",),
        _build,
        _topic_find,
        graph_names=False,
    ),
    Verb(("service", "type"), "print a service's type", ("SERVICE",), _build, _service_type),
    Verb(
        ("service", "find"),
        "list the services of a type",
        ("TYPE",),
        _build,
        _service_find,
        graph_names=False,
    ),
]
