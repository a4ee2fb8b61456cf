"""``rmb node list`` and ``rmb graph [--watch]``: the robot's ROS graph, and
a live stream of nodes, topics, services and actions appearing and leaving.

One event per line: ``+ topic /odom nav_msgs/msg/Odometry``, ``- node
/talker``; with ``--json`` one object per line, ``{"event": "added" |
"removed", "kind": "node" | "topic" | "service" | "action", "name": ...,
"type": ... | null}``. Topics and services follow the client's watchers
(each transport's own discovery: Foxglove's advertise and unadvertise,
rosbridge's ``/rosapi`` poll, Zenoh's liveliness tokens); nodes are polled
with :meth:`Client.nodes` every ``--interval`` seconds where the transport
reports them (not over Foxglove). An action is shown once for its
``_action/send_goal`` service, whose ``_action/`` services are not listed
again."""

from __future__ import annotations

import argparse
from collections.abc import AsyncIterator, Callable, Iterable
from functools import partial
from typing import Any, Final, Literal

import anyio

from .._core._client import Client
from .._errors import NotSupportedError
from ._common import open_robot, out, warn
from ._format import UsageError, json_line
from ._verb import Verb

__all__ = ["VERBS", "Entry", "changes", "graph_entries"]

Kind = Literal["node", "topic", "service", "action"]
Entry = tuple[Kind, str, str | None]
"""One thing of the graph: its kind, name and type (None for a node)."""

_SEND_GOAL: Final = "/_action/send_goal"


def graph_entries(kind: str, items: Iterable[Any]) -> set[Entry]:
    """The entries of a topic or service list (``TopicInfo``/``ServiceInfo``);
    actions are read off their ``send_goal`` services."""
    entries: set[Entry] = set()
    for item in items:
        if kind == "topic":
            entries.add(("topic", item.name, item.schema_name or None))
            continue
        name, type_ = item.name, item.type or None
        if name.endswith(_SEND_GOAL):
            action_type = type_.removesuffix("_SendGoal") if type_ else None
            entries.add(("action", name.removesuffix(_SEND_GOAL), action_type))
        elif "/_action/" not in name:
            entries.add(("service", name, type_))
    return entries


def changes(before: set[Entry], after: set[Entry]) -> list[tuple[bool, Entry]]:
    """``(added, entry)`` pairs, removals first, each sorted by kind and name.
    A type change is a removal and an addition, except a type learnt late
    (rosbridge looks service types up after listing them): that is no
    event."""
    untyped = {(kind, name) for kind, name, type_ in before if type_ is None}
    typed_late = {e for e in after - before if e[2] is not None and (e[0], e[1]) in untyped}
    settled = {(kind, name) for kind, name, _ in typed_late}
    gone = [e for e in before - after if not (e[2] is None and (e[0], e[1]) in settled)]
    new = [e for e in after - before if e not in typed_late]

    def order(e: Entry) -> tuple[str, str, str]:
        return (e[0], e[1], e[2] or "")

    return [(False, e) for e in sorted(gone, key=order)] + [
        (True, e) for e in sorted(new, key=order)
    ]


def _print(added: bool, entry: Entry, as_json: bool) -> None:
    kind, name, type_ = entry
    if as_json:
        event = "added" if added else "removed"
        out(json_line({"event": event, "kind": kind, "name": name, "type": type_}))
    else:
        out(f"{'+' if added else '-'} {kind} {name}" + (f" {type_}" if type_ else ""))


async def _follow(
    lists: AsyncIterator[list[Any]],
    entries: Callable[[list[Any]], set[Entry]],
    watch: bool,
    as_json: bool,
) -> None:
    known: set[Entry] = set()
    async for items in lists:
        now = entries(items)
        for added, entry in changes(known, now):
            _print(added, entry, as_json)
        known = now
        if not watch:
            return


async def _nodes_now(robot: Client) -> set[Entry]:
    return {("node", name, None) for name in await robot.nodes()}


async def _watch_nodes(robot: Client, known: set[Entry], interval: float, as_json: bool) -> None:
    """Every ``interval`` seconds, the changes since ``known``."""
    while True:
        await anyio.sleep(interval)
        now = await _nodes_now(robot)
        for added, entry in changes(known, now):
            _print(added, entry, as_json)
        known = now


async def _graph(ns: argparse.Namespace) -> int:
    if not ns.interval > 0:
        raise UsageError(f"--interval must be a positive number of seconds, got {ns.interval!r}")
    async with open_robot(ns) as robot:
        # the nodes first, then topics, services and actions (a snapshot's order)
        nodes: set[Entry] | None
        try:
            nodes = await _nodes_now(robot)
        except NotSupportedError as exc:
            warn(f"no nodes: {exc}")
            nodes = None
        for added, entry in changes(set(), nodes or set()):
            _print(added, entry, ns.json)
        async with anyio.create_task_group() as tg:
            for kind, lists in (
                ("topic", robot.watch_topics()),
                ("service", robot.watch_services()),
            ):
                tg.start_soon(_follow, lists, partial(graph_entries, kind), ns.watch, ns.json)
            if ns.watch and nodes is not None:
                tg.start_soon(_watch_nodes, robot, nodes, ns.interval, ns.json)
    return 0


async def _node_list(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        for name in await robot.nodes():
            out(json_line({"name": name}) if ns.json else name)
    return 0


def _json_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="one JSON object per line")


def _build_graph(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-w", "--watch", action="store_true", help="then print every change until stopped"
    )
    p.add_argument(
        "--interval",
        type=float,
        default=1.0,
        metavar="S",
        help="seconds between two looks at the node list (default 1)",
    )
    _json_option(p)


# the verbs' help lines, as the index (_table) has them
_NODES = "list the graph's nodes (Zenoh, rosbridge, Foxglove's connection graph; --json)"
_GRAPH = "the graph's nodes, topics, services, actions; --watch: every change"

VERBS = [
    Verb(("node", "list"), _NODES, (), _json_option, _node_list),
    Verb(("nodes",), _NODES, (), _json_option, _node_list, hidden=True),
    Verb(("graph",), _GRAPH, (), _build_graph, _graph),
]
