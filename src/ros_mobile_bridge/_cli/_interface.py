"""``rmb interface list|packages|package|show|proto``, shaped like ``ros2
interface``: they read the bundled ROS 2 Jazzy interfaces and the local
workspace (``--interface-path``, ``$AMENT_PREFIX_PATH``) with no robot. ``show``
with a robot address prints the robot's definition instead and says so when it
differs from the local one."""

from __future__ import annotations

import argparse
import os
from collections.abc import Callable, Sequence
from typing import Any

from .._connect import connect
from .._errors import SchemaError
from .._options import ClientOptions
from ..codec import (
    CodecRegistry,
    FieldDef,
    Interface,
    find_interface,
    interface_names,
    interface_paths_for,
)
from ._common import nearest, out, warn
from ._format import dump_yaml, json_line, plain
from ._verb import Verb, run_signalled

__all__ = ["VERBS", "render_interface"]

_KINDS = {"msg": "Messages", "srv": "Services", "action": "Actions"}
_PRIMITIVES = frozenset(
    {
        "bool",
        "byte",
        "char",
        "float32",
        "float64",
        "int8",
        "uint8",
        "int16",
        "uint16",
        "int32",
        "uint32",
        "int64",
        "uint64",
        "string",
        "wstring",
        "time",
        "duration",
    }
)

Lookup = Callable[[str], "Interface | None"]


# -- rendering, as ros2 interface show prints a definition --------------------------------------


def _comment_at(line: str) -> int:
    """Where the line's comment starts (``len(line)`` when it has none): the
    first ``#`` outside a quoted string default."""
    quote = ""
    for i, ch in enumerate(line):
        if quote:
            if ch == quote:
                quote = ""
        elif ch in "\"'":
            quote = ch
        elif ch == "#":
            return i
    return len(line)


def _nested_type(code: str, package: str) -> str | None:
    """The full name of the message a field line refers to, or None for a
    primitive field, a constant, a separator or a blank line."""
    parts = code.split()
    if len(parts) < 2 or "=" in code:
        return None
    base = parts[0].split("[", 1)[0].split("<=", 1)[0]
    if base in _PRIMITIVES:
        return None
    pieces = base.split("/")
    if len(pieces) == 1:
        return f"{package}/msg/{base}"
    if len(pieces) == 2:
        return f"{pieces[0]}/msg/{pieces[1]}"
    return base


def render_interface(
    interface: Interface,
    lookup: Lookup,
    *,
    comments: bool = True,
    nested_comments: bool = False,
    indent: int = 0,
) -> list[str]:
    """The lines ``ros2 interface show`` prints for ``interface``: its text
    (comments and blank lines only when ``comments``), each field of a
    message type followed by that type's definition indented one tab
    further (its comments only when ``nested_comments``). A nested type
    ``lookup`` cannot find is printed as its field line alone."""
    package = interface.name.split("/", 1)[0]
    pad = "\t" * indent
    lines: list[str] = []
    for raw in interface.text.splitlines():
        raw = raw.rstrip()
        cut = _comment_at(raw)
        code = raw[:cut].rstrip()
        if comments:
            if raw or indent == 0:
                lines.append(pad + raw if raw else "")
        elif code:
            lines.append(pad + code)
        nested = _nested_type(code, package)
        if nested is None:
            continue
        found = lookup(nested)
        if found is not None and found.kind == "msg":
            lines.extend(
                render_interface(
                    found,
                    lookup,
                    comments=nested_comments,
                    nested_comments=nested_comments,
                    indent=indent + 1,
                )
            )
    return lines


def _fields_lines(fields_of: Callable[[str], list[FieldDef]], name: str, indent: int) -> list[str]:
    lines: list[str] = []
    for f in fields_of(name):
        lines.append("\t" * indent + f"{_type_text(f)} {f.name}")
        if "/" in f.type:
            lines.extend(_fields_lines(fields_of, f.type, indent + 1))
    return lines


def _type_text(f: FieldDef) -> str:
    base = f.type
    if not f.array and f.upper_bound is not None and base == "string":
        base = f"string<={f.upper_bound}"
    if f.array:
        if f.array_length is not None:
            base += f"[{f.array_length}]"
        elif f.upper_bound is not None:
            base += f"[<={f.upper_bound}]"
        else:
            base += "[]"
    return base


def _parts(name: str) -> list[str]:
    if "/srv/" in name:
        return [f"{name}_Request", f"{name}_Response"]
    if "/action/" in name:
        return [f"{name}_Goal", f"{name}_Result", f"{name}_Feedback"]
    return [name]


def _shape(fields: list[FieldDef]) -> list[tuple[Any, ...]]:
    return [(f.name, f.type, f.array, f.array_length, f.upper_bound) for f in fields]


# -- the verbs --------------------------------------------------------------------------------


def _paths(ns: argparse.Namespace) -> tuple[str, ...]:
    return tuple(getattr(ns, "interface_path", None) or ())


def _finder(ns: argparse.Namespace) -> Lookup:
    paths = _paths(ns)
    return lambda name: find_interface(name, paths=paths)


def _unknown(name: str, ns: argparse.Namespace) -> int:
    close = nearest(name, interface_names(paths=_paths(ns)))
    hint = f"; nearest: {', '.join(close)}" if close else ""
    where = " (not bundled and not in the workspace"
    where += f" {os.pathsep.join(_paths(ns))})" if _paths(ns) else ")"
    warn(f"unknown interface {name!r}{where}{hint}")
    return 1


def _list(ns: argparse.Namespace) -> int:
    wanted = [k for k, flag in (("msg", ns.only_msgs), ("srv", ns.only_srvs)) if flag]
    if ns.only_actions:
        wanted.append("action")
    kinds = wanted or list(_KINDS)
    names = interface_names(paths=_paths(ns))
    for kind in kinds:
        if not ns.json:
            out(f"{_KINDS[kind]}:")
        for name in names:
            if name.split("/")[1] == kind:
                out(json_line({"name": name, "kind": kind}) if ns.json else f"    {name}")
    return 0


def _packages(ns: argparse.Namespace) -> int:
    for package in sorted({n.split("/", 1)[0] for n in interface_names(paths=_paths(ns))}):
        out(json_line({"package": package}) if ns.json else package)
    return 0


def _package(ns: argparse.Namespace) -> int:
    names = [n for n in interface_names(paths=_paths(ns)) if n.split("/", 1)[0] == ns.package]
    if not names:
        packages = {n.split("/", 1)[0] for n in interface_names(paths=_paths(ns))}
        close = nearest(ns.package, packages)
        hint = f"; nearest: {', '.join(close)}" if close else ""
        warn(f"unknown package {ns.package!r}{hint}")
        return 1
    for name in names:
        out(json_line({"name": name, "kind": name.split("/")[1]}) if ns.json else name)
    return 0


def _show(ns: argparse.Namespace) -> int:
    ns.url = ns.url or ns.robot
    if ns.url:
        return run_signalled(_show_robot, ns, backend=getattr(ns, "backend", None) or "asyncio")
    found = find_interface(ns.type, paths=_paths(ns))
    if found is None:
        return _unknown(ns.type, ns)
    lines = render_interface(
        found,
        _finder(ns),
        comments=not ns.no_comments,
        nested_comments=ns.all_comments and not ns.no_comments,
    )
    if ns.json:
        record = {"type": found.name, "kind": found.kind, "origin": found.origin}
        out(json_line({**record, "text": "\n".join(lines)}))
        return 0
    for line in lines:
        out(line)
    return 0


async def _show_robot(ns: argparse.Namespace) -> int:
    """The robot's definition (rosbridge: /rosapi; Zenoh: the node's
    get_type_description; Foxglove: the channel schemas), fields only."""
    options = ClientOptions(connect_timeout=ns.timeout, interface_paths=_paths(ns))
    async with connect(ns.url, protocol=ns.protocol or "auto", options=options) as robot:
        sections: list[list[str]] = []
        for part in _parts(ns.type):
            try:
                robot.schema_definition(part)
            except SchemaError:
                await robot.fetch_definition(part)
            try:
                sections.append(_fields_lines(robot.schema_definition, part, 0))
            except SchemaError:
                warn(f"unknown type {ns.type!r}: the robot does not know it and it is not local")
                return 1
        text = "\n---\n".join("\n".join(s) for s in sections)
        out(json_line({"type": ns.type, "origin": "robot", "text": text}) if ns.json else text)
        local = CodecRegistry(interfaces=interface_paths_for(_paths(ns)))
        for part in _parts(ns.type):
            try:
                mine = local.definition(part)
            except SchemaError:
                warn(f"{part}: the robot's definition is shown; there is no local one")
                continue
            theirs = robot.schema_definition(part)
            if _shape(mine) != _shape(theirs):
                mine_names = [f.name for f in mine]
                theirs_names = [f.name for f in theirs]
                warn(
                    f"{part}: the robot's definition differs from the local one "
                    f"(robot fields: {', '.join(theirs_names) or 'none'}; "
                    f"local: {', '.join(mine_names) or 'none'})"
                )
    return 0


def _proto(ns: argparse.Namespace) -> int:
    if find_interface(ns.type, paths=_paths(ns)) is None:
        return _unknown(ns.type, ns)
    registry = CodecRegistry(interfaces=interface_paths_for(_paths(ns)))
    template = registry.template(_parts(ns.type)[0])
    if ns.json:
        out(json_line({"type": ns.type, "prototype": plain(template)}))
        return 0
    out(f'"{dump_yaml(template).rstrip()}"')
    return 0


def _build_common(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--interface-path",
        action="append",
        metavar="PATH",
        help="a colcon install prefix, share directory or package to read (repeatable; "
        "$AMENT_PREFIX_PATH is read too)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per line")


def _build_list(p: argparse.ArgumentParser) -> None:
    _build_common(p)
    p.add_argument("-m", "--only-msgs", action="store_true", help="messages only")
    p.add_argument("-s", "--only-srvs", action="store_true", help="services only")
    p.add_argument("-a", "--only-actions", action="store_true", help="actions only")


def _build_show(p: argparse.ArgumentParser) -> None:
    _build_common(p)
    group = p.add_mutually_exclusive_group()
    group.add_argument("--all-comments", action="store_true", help="nested types' comments too")
    group.add_argument("--no-comments", action="store_true", help="no comments at all")
    p.add_argument(
        "-u", "--url", default=None, help="show the robot's definition instead (any transport)"
    )
    p.add_argument("--protocol", default=None, help="the robot's transport (default: auto)")
    p.add_argument("--timeout", type=float, default=10.0, metavar="S", help="connect timeout")


def verbs(show_args: Sequence[str] = ("TYPE", "ROBOT?")) -> list[Verb]:
    """The ``interface`` verbs (no robot needed; ``show`` takes one)."""
    return [
        Verb(
            ("interface", "list"),
            "list the interfaces known without a robot",
            (),
            _build_list,
            run_sync=_list,
        ),
        Verb(
            ("interface", "packages"),
            "list the interface packages",
            (),
            _build_common,
            run_sync=_packages,
        ),
        Verb(
            ("interface", "package"),
            "list one package's interfaces",
            ("PACKAGE",),
            _build_common,
            run_sync=_package,
        ),
        Verb(
            ("interface", "show"),
            "print a definition as ros2 does (comments, nested types); with a robot, the robot's",
            tuple(show_args),
            _build_show,
            run_sync=_show,
            graph_names=False,
        ),
        Verb(
            ("interface", "proto"),
            "print a YAML prototype of a message, or of a service's request / action's goal",
            ("TYPE",),
            _build_common,
            run_sync=_proto,
        ),
    ]


VERBS = verbs()
