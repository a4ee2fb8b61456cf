"""The index of ``rmb``'s verbs: each verb's words, its one-line help and the
module that defines it. ``rmb --help``, ``rmb --version`` and a group's help
(``rmb topic --help``) are answered from here alone, so they import none of
the verb modules (nor anyio, the client or the codec); the module of a verb
is imported only when that verb runs or its own ``--help`` is asked for.

Each entry must match the :class:`~._verb.Verb` its module lists (words,
help, hidden); ``tests/test_cli_help.py`` checks that, so the index cannot
drift from the verbs."""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["ENTRIES", "GROUP_HELP", "Entry", "group_entries", "groups"]


@dataclass(frozen=True)
class Entry:
    """One verb: ``path`` its words, ``module`` the ``_cli`` module listing
    it in ``VERBS``, ``help`` its line, ``hidden`` when ``rmb --help`` leaves
    it out (a ros2 spelling of a shorter verb; its group's help lists it)."""

    path: tuple[str, ...]
    module: str
    help: str
    hidden: bool = False


_ECHO = "print a topic's messages as YAML (--json, --csv, --flow-style)"
_HZ = "a topic's message rate every second, counted on arrival (--json)"
_BW = "a topic's bandwidth every second, counted on arrival (--json)"
_DELAY = "header.stamp against arrival every second, as ros2 topic delay (--json)"
_NODES = "list the graph's nodes (Zenoh, rosbridge, Foxglove's connection graph; --json)"
_PUB = "publish a message (YAML) at 1 Hz until stopped (-r, --once, -t)"
_TOPICS = "list topics (-t types, -v publishers/subscribers, -c count, --json)"
_SERVICES = "list services (-t types, -c count, --json)"
_CALL = "call a service with a YAML request (ros2's SERVICE TYPE REQUEST form too)"

ENTRIES: tuple[Entry, ...] = (
    Entry(("demo",), "_demo", "run the embedded demo robot and drive it (--serve: only serve it)"),
    Entry(("topics",), "_topic", _TOPICS),
    Entry(("topic", "list"), "_topic", _TOPICS, hidden=True),
    Entry(("echo",), "_topic", _ECHO),
    Entry(("topic", "echo"), "_topic", _ECHO, hidden=True),
    Entry(("hz",), "_rate", _HZ),
    Entry(("topic", "hz"), "_rate", _HZ, hidden=True),
    Entry(("bw",), "_rate", _BW),
    Entry(("topic", "bw"), "_rate", _BW, hidden=True),
    Entry(("delay",), "_rate", _DELAY),
    Entry(("topic", "delay"), "_rate", _DELAY, hidden=True),
    Entry(("info",), "_topic", "the server (protocol, capabilities), or a topic (--json)"),
    Entry(("topic", "info"), "_topic", "a topic's type and counts (--json)", hidden=True),
    Entry(("pub",), "_topic", _PUB),
    Entry(("topic", "pub"), "_topic", _PUB, hidden=True),
    Entry(("topic", "type"), "_lookup", "print a topic's type"),
    Entry(("topic", "find"), "_lookup", "list the topics of a type"),
    Entry(("services",), "_ros", _SERVICES),
    Entry(("service", "list"), "_ros", _SERVICES, hidden=True),
    Entry(("call",), "_ros", _CALL),
    Entry(("service", "call"), "_ros", _CALL, hidden=True),
    Entry(("service", "type"), "_lookup", "print a service's type"),
    Entry(("service", "find"), "_lookup", "list the services of a type"),
    Entry(("param", "list"), "_ros", "list parameter names (--values, --json)"),
    Entry(("param", "get"), "_ros", "print parameters' values ([NODE] NAME ...)"),
    Entry(("param", "set"), "_ros", "set a parameter (YAML value; [NODE] NAME VALUE)"),
    Entry(("param", "dump"), "_ros", "print every parameter as ros2 param dump's YAML"),
    Entry(("params",), "_ros", "rmb 0.1's list/get/--set NAME=VALUE, printing JSON", hidden=True),
    Entry(
        ("action", "send"), "_ros", "send an action goal (YAML), print feedback; Ctrl-C cancels it"
    ),
    Entry(("interface", "list"), "_interface", "list the interfaces known without a robot"),
    Entry(("interface", "packages"), "_interface", "list the interface packages"),
    Entry(("interface", "package"), "_interface", "list one package's interfaces"),
    Entry(
        ("interface", "show"),
        "_interface",
        "print a definition as ros2 does (comments, nested types); with a robot, the robot's",
    ),
    Entry(
        ("interface", "proto"),
        "_interface",
        "print a YAML prototype of a message, or of a service's request / action's goal",
    ),
    Entry(
        ("interface", "generate"),
        "_generate",
        "write typed Python classes for your own interface packages (--out DIR)",
    ),
    Entry(
        ("record",),
        "_record",
        "record topics to an MCAP file (every topic when none is named; Ctrl-C stops, "
        "the file is complete either way)",
    ),
    Entry(("node", "list"), "_graph", _NODES),
    Entry(("nodes",), "_graph", _NODES, hidden=True),
    Entry(
        ("graph",), "_graph", "the graph's nodes, topics, services, actions; --watch: every change"
    ),
    Entry(("bag", "info"), "_bag", "summarise a recording as ros2 bag info does (no robot needed)"),
)
"""Every verb, in the order ``rmb --help`` lists them."""

GROUP_HELP: dict[str, str] = {
    "topic": "topics: list, echo, rates, publish (as ros2 topic)",
    "service": "services: list, call, types (as ros2 service)",
    "param": "parameters: list, get, set, dump (as ros2 param)",
    "action": "actions: send a goal (as ros2 action)",
    "interface": "interface definitions, no robot needed (as ros2 interface)",
    "node": "nodes: list (as ros2 node)",
    "bag": "recordings: summarise a file (as ros2 bag; rmb record writes them)",
}
"""A line per verb group (the first word of verbs of two words)."""


def groups() -> list[str]:
    """The verb groups: first words of verbs of two or more words."""
    return sorted({e.path[0] for e in ENTRIES if len(e.path) > 1})


def group_entries(group: str) -> list[Entry]:
    """The verbs of ``group`` (hidden ones too: the ros2 spellings), in
    table order."""
    return [e for e in ENTRIES if len(e.path) > 1 and e.path[0] == group]
