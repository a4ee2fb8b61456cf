"""``rmb`` verbs for services, parameters, interfaces and actions, shaped
like ``ros2 service|param|interface|action``."""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Mapping
from typing import Any

from .._core._action import ActionGoal
from .._core._client import Client
from .._errors import ParameterError, RosBridgeError
from ._common import check_type, graph_name, missing_line, open_robot, out, warn
from ._format import (
    UsageError,
    check_fields,
    dump_flow,
    dump_yaml,
    finite_or_none,
    json_line,
    parse_yaml_mapping,
    parse_yaml_value,
    plain,
)
from ._verb import Verb

__all__ = ["VERBS"]


# -- services --------------------------------------------------------------------------------


async def _services(ns: argparse.Namespace) -> int:
    """``services`` / ``service list``: names; ``-t`` with types; ``-c`` the
    count; ``--json`` one ``{"name", "type"}`` object per service (or
    ``{"count": N}``)."""
    async with open_robot(ns) as robot:
        services = sorted(robot.services, key=lambda s: s.name)
    if ns.count_services:
        out(json_line({"count": len(services)}) if ns.json else str(len(services)))
        return 0
    for svc in services:
        if ns.json:
            out(json_line({"name": svc.name, "type": svc.type}))
        else:
            out(f"{svc.name}  [{svc.type}]" if ns.show_types else svc.name)
    return 0


def _build_services(p: argparse.ArgumentParser) -> None:
    p.add_argument("-t", "--show-types", action="store_true", help="print each service's type")
    p.add_argument(
        "-c", "--count-services", action="store_true", help="print the number of services only"
    )
    p.add_argument("--json", action="store_true", help="one JSON object per line")


_TYPE = re.compile(r"^[A-Za-z]\w*/(\w+/)?[A-Za-z]\w*$")


def _type_and_request(ns: argparse.Namespace) -> tuple[str | None, str]:
    """``call SERVICE [TYPE] [REQUEST]``: the second argument is ros2's
    TYPE when it reads as one (``std_srvs/srv/SetBool``), else the request."""
    second, third = ns.type, ns.request
    if second is not None and third is None and not _TYPE.match(second):
        return None, second
    if second is not None and not _TYPE.match(second):
        raise UsageError(f"{second!r} is not a service type (pkg/srv/Type)")
    return second, third or ""


async def _call(ns: argparse.Namespace) -> int:
    given, text = _type_and_request(ns)
    request = parse_yaml_mapping(text, "the request")
    async with open_robot(ns) as robot:
        svc = next((s for s in robot.services if s.name == ns.service), None)
        if svc is None and robot.services:
            warn(missing_line("service", ns.service, [s.name for s in robot.services]))
            return 1
        if given is not None:
            check_type("srv", ns.service, given, svc.type if svc else None)
        service_type = svc.type if svc is not None and svc.type else given
        if service_type:
            check_fields(
                robot, _part(service_type, "Request"), request, f"call_service {ns.service}"
            )
        reply = await robot.call_service(ns.service, request, timeout=ns.call_timeout)
    value = finite_or_none(plain(reply))
    if ns.json:
        out(json_line({"service": ns.service, "type": service_type, "response": value}))
    else:
        out(json.dumps(value, indent=2))
    return 0


def _part(service_type: str, which: str) -> str:
    return f"{service_type}_{which}"


def _build_call(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--call-timeout", type=float, default=10.0, metavar="S", help="seconds (default 10)"
    )
    p.add_argument("--json", action="store_true", help='one line: {"service", "type", "response"}')


# -- parameters ------------------------------------------------------------------------------
#
# rosbridge and Zenoh name a node's parameter ``/node:name``; a Foxglove
# server's parameters belong to no node (the server stands for one), so a
# NODE given there selects nothing and is not checked.


def _flat(robot: Client) -> bool:
    return robot.protocol == "foxglove-ws"


def _qualified(robot: Client, node: str | None, name: str) -> str:
    """The name the transport knows ``node``'s parameter ``name`` by."""
    return name if node is None or _flat(robot) or ":" in name else f"{node}:{name}"


def _shown(node: str | None, name: str) -> str:
    """A parameter's name as printed: without the node the user named."""
    return name.removeprefix(f"{node}:") if node else name


def _node_first(names: list[str]) -> tuple[str | None, list[str]]:
    """ros2's ``NODE NAME ...`` form: a first argument that is an absolute
    name (``/demo_robot``) before at least one parameter name is the node."""
    if len(names) >= 2 and names[0].startswith("/") and ":" not in names[0]:
        return graph_name(names[0], "node"), names[1:]
    return None, names


def _node_of(robot: Client, name: str) -> str:
    """The node a listed parameter belongs to (``/node:name``); over
    Foxglove the server's name made a node name."""
    if ":" in name and name.startswith("/"):
        return name.split(":", 1)[0]
    return "/" + re.sub(r"\W", "_", robot.server_info.name or "server")


async def _param_list(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        values = await robot.list_parameters()
        flat = _flat(robot)
    node = ns.node
    if node is not None and not flat:
        values = {k: v for k, v in values.items() if k.startswith(f"{node}:")}
    for name in sorted(values):
        if ns.json:
            record = {"node": node, "name": _shown(node, name), "value": plain(values[name])}
            out(json_line(record))
        else:
            shown = _shown(node, name)
            out(f"{shown}: {_flow(values[name])}" if ns.values else shown)
    return 0


def _flow(value: Any) -> str:
    return dump_flow(plain(value))


async def _param_get(ns: argparse.Namespace) -> int:
    node, names = _node_first(list(ns.name))
    reasons: dict[str, str] = {}
    async with open_robot(ns) as robot:
        if node is None and len(names) >= 2 and not _flat(robot) and ":" not in names[0]:
            # a relative node (rmb_params speed): the first name when the robot has such a node
            first = graph_name(names[0], "node")
            if any(k.startswith(f"{first}:") for k in await robot.list_parameters()):
                node, names = first, names[1:]
        wanted = [_qualified(robot, node, n) for n in names]
        try:
            values = await robot.get_parameters(wanted)
        except ParameterError as exc:  # the found ones are printed, each missing one said
            values, reasons = exc.values, exc.reasons
    for name in wanted:
        if name in values:
            if ns.json:
                record = {"node": node, "name": _shown(node, name), "value": plain(values[name])}
                out(json_line(record))
            else:
                out(f"{_shown(node, name)}: {_flow(values[name])}")
    for name, why in reasons.items():
        warn(f"parameter {_shown(node, name)!r}: {why}")
    return 1 if reasons else 0


async def _set_and_check(
    robot: Client, wanted: Mapping[str, Any], node: str | None = None, as_json: bool = False
) -> int:
    """Set ``wanted``, print what the server reports, exit 1 unless every
    value was taken as given."""
    reasons: dict[str, str] = {}
    try:
        result = await robot.set_parameters(wanted)
    except ParameterError as exc:
        result, reasons = exc.values, exc.reasons
    for name, value in wanted.items():
        got = result.get(name, _ABSENT)
        ok = name not in reasons
        if as_json:
            now = None if got is _ABSENT else plain(got)
            record = {"node": node, "name": _shown(node, name), "value": now, "set": ok}
            if not ok:
                record["reason"] = reasons[name]
            out(json_line(record))
        if not ok:
            warn(
                f"setting parameter {_shown(node, name)} to {_flow(value)} failed: {reasons[name]}"
            )
        elif not as_json:
            out(f"Set parameter successful: {_shown(node, name)}: {_flow(got)}")
    return 1 if reasons else 0


_ABSENT: Any = object()


async def _param_set(ns: argparse.Namespace) -> int:
    node, name, text = None, ns.name, ns.value
    if ns.arg is not None:  # ros2's NODE NAME VALUE
        node, name, text = graph_name(ns.name, "node"), ns.value, ns.arg
    value = parse_yaml_value(text, f"the value of {name}")
    async with open_robot(ns) as robot:
        full = _qualified(robot, node, name)
        return await _set_and_check(robot, {full: value}, node, ns.json)


def _nest(values: Mapping[str, Any]) -> dict[str, Any]:
    """Dotted parameter names as nested mappings, as ``ros2 param dump``
    writes them (``a.b: 1`` is ``a: {b: 1}``), keys sorted."""
    tree: dict[str, Any] = {}
    for name in sorted(values):
        *path, last = name.split(".")
        here = tree
        for part in path:
            nxt = here.setdefault(part, {})
            if not isinstance(nxt, dict):  # a value and a prefix of the same name: keep both
                nxt = here[part + "."] = {}
            here = nxt
        here[last] = plain(values[name])
    return tree


async def _param_dump(ns: argparse.Namespace) -> int:
    """``ros2 param dump``'s YAML: ``/node:`` then ``ros__parameters:``
    then the node's values; every node's when no NODE is named."""
    async with open_robot(ns) as robot:
        values = await robot.list_parameters()
        by_node: dict[str, dict[str, Any]] = {}
        for full, value in values.items():
            node = _node_of(robot, full) if not (_flat(robot) and ns.node) else ns.node
            by_node.setdefault(node, {})[full.split(":", 1)[1] if ":" in full else full] = value
    if ns.node is not None:
        if ns.node not in by_node:
            warn(missing_line("node", ns.node, by_node))
            return 1
        by_node = {ns.node: by_node[ns.node]}
    for node in sorted(by_node):
        params = _nest(by_node[node])
        if ns.json:
            out(json_line({"node": node, "parameters": finite_or_none(params)}))
        else:
            out(dump_yaml({node: {"ros__parameters": params}}).rstrip("\n"))
    return 0


async def _params(ns: argparse.Namespace) -> int:
    """rmb 0.1's ``params [NAME ...] [--set NAME=VALUE ...]``, printing JSON."""
    wanted: dict[str, Any] = {}
    for item in ns.set or ():
        name, sep, text = item.partition("=")
        if not sep or not name:
            raise UsageError(f"--set wants NAME=VALUE (a YAML value), got {item!r}")
        wanted[name] = parse_yaml_value(text, f"the value of {name}")
    async with open_robot(ns) as robot:
        bad: list[str] = []
        try:
            if wanted:
                result = await robot.set_parameters(wanted)
            elif ns.name:
                result = await robot.get_parameters(ns.name)
            else:
                result = await robot.list_parameters()
        except ParameterError as exc:
            result, bad = exc.values, list(exc.reasons)
    out(json.dumps(finite_or_none(plain(result)), indent=2, sort_keys=True))
    if bad:
        warn(f"{'not set' if wanted else 'not found'}: {', '.join(bad)}")
        return 1
    return 0


def _build_params(p: argparse.ArgumentParser) -> None:
    p.add_argument("--set", action="append", metavar="NAME=VALUE", help="set (repeatable)")


def _build_param_list(p: argparse.ArgumentParser) -> None:
    p.add_argument("--values", action="store_true", help="print each parameter's value too")
    _json_option(p, '{"node", "name", "value"}')


def _json_option(p: argparse.ArgumentParser, fields: str) -> None:
    p.add_argument("--json", action="store_true", help=f"one JSON object per line: {fields}")


# -- action send -----------------------------------------------------------------------------


async def _action_send(ns: argparse.Namespace) -> int:
    """``action send``: the goal is printed once sent (a transport without
    actions refuses first, so nothing is printed before that error);
    ``--json``: ``{"goal"}``, then ``{"feedback"}`` per feedback, then
    ``{"status", "result"}``."""
    import anyio

    goal = parse_yaml_mapping(ns.goal or "", "the goal")
    async with open_robot(ns) as robot:
        check_fields(robot, f"{ns.type}_Goal", goal, f"send_action_goal {ns.action}")
        async with (
            robot.send_action_goal(ns.action, ns.type, goal) as handle,
            anyio.create_task_group() as tg,
        ):
            if ns.json:
                out(json_line({"action": ns.action, "type": ns.type, "goal": plain(goal)}))
            else:
                out(f"Sending goal:\n{_indented(goal)}")

            async def feedback() -> None:
                async for values in handle.feedback:
                    if ns.json:
                        out(json_line({"feedback": finite_or_none(plain(values))}))
                    elif ns.feedback:
                        out(f"Feedback:\n{_indented(values)}")

            tg.start_soon(feedback)
            try:
                outcome = await handle.result()
            except anyio.get_cancelled_exc_class():
                await _cancel_goal(handle, ns.json)  # Ctrl-C (or another signal)
                raise
            finally:
                tg.cancel_scope.cancel()
    if ns.json:
        result = finite_or_none(plain(outcome.result))
        out(json_line({"status": outcome.status, "result": result}))
    else:
        out(f"Result:\n{_indented(outcome.result)}")
        out(f"Goal finished with status: {outcome.status.upper()}")
    return 0 if outcome.status == "succeeded" else 1


async def _cancel_goal(handle: ActionGoal, as_json: bool = False) -> None:
    """Cancel the goal and say how it ended, shielded, within 3 s."""
    import anyio

    with anyio.CancelScope(shield=True), anyio.move_on_after(3.0):
        warn("canceling the goal")
        try:
            await handle.cancel()
            outcome = await handle.result()
        except RosBridgeError as exc:
            warn(f"the goal did not end cleanly: {exc}")
        else:
            if as_json:
                out(json_line({"status": outcome.status, "result": None}))
            else:
                out(f"Goal finished with status: {outcome.status.upper()}")


def _indented(value: Any) -> str:
    text = dump_yaml(plain(value)).rstrip("\n")
    return "\n".join("    " + line for line in text.splitlines())


def _build_action(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--no-feedback",
        dest="feedback",
        action="store_false",
        help="do not print feedback (printed by default)",
    )
    _json_option(p, '{"action", "type", "goal"}, {"feedback"} ..., {"status", "result"}')


def _build_param_get(p: argparse.ArgumentParser) -> None:
    _json_option(p, '{"node", "name", "value"}')


def _build_param_set(p: argparse.ArgumentParser) -> None:
    _json_option(p, '{"node", "name", "value", "set"}')


def _build_param_dump(p: argparse.ArgumentParser) -> None:
    _json_option(p, '{"node", "parameters"}')


_SERVICES = "list services (-t types, -c count, --json)"
_CALL = "call a service with a YAML request (ros2's SERVICE TYPE REQUEST form too)"
_CALL_ARGS = ("SERVICE", "TYPE?", "REQUEST?")

VERBS = [
    Verb(("services",), _SERVICES, build=_build_services, run=_services),
    Verb(("service", "list"), _SERVICES, build=_build_services, run=_services, hidden=True),
    Verb(("call",), _CALL, _CALL_ARGS, _build_call, _call),
    Verb(("service", "call"), _CALL, _CALL_ARGS, _build_call, _call, hidden=True),
    Verb(
        ("param", "list"),
        "list parameter names (--values, --json)",
        ("NODE?",),
        _build_param_list,
        _param_list,
        graph_names=False,
    ),
    Verb(
        ("param", "get"),
        "print parameters' values ([NODE] NAME ...)",
        ("NAME+",),
        _build_param_get,
        _param_get,
        graph_names=False,
        usage="[NODE] NAME [NAME ...]",
    ),
    Verb(
        ("param", "set"),
        "set a parameter (YAML value; [NODE] NAME VALUE)",
        ("NAME", "VALUE", "ARG?"),
        _build_param_set,
        _param_set,
        graph_names=False,
        usage="[NODE] NAME VALUE",
    ),
    Verb(
        ("param", "dump"),
        "print every parameter as ros2 param dump's YAML",
        ("NODE?",),
        _build_param_dump,
        _param_dump,
        graph_names=False,
    ),
    Verb(
        ("params",),
        "rmb 0.1's list/get/--set NAME=VALUE, printing JSON",
        ("NAME*",),
        _build_params,
        _params,
        graph_names=False,
        hidden=True,
    ),
    Verb(
        ("action", "send"),
        "send an action goal (YAML), print feedback; Ctrl-C cancels it",
        ("ACTION", "TYPE", "GOAL?"),
        _build_action,
        _action_send,
    ),
]
