"""``rmb`` verbs for services, parameters, interfaces and actions, shaped
like ``ros2 service|param|interface|action``."""

from __future__ import annotations

import argparse
import json
from collections.abc import Mapping
from typing import Any

from .._action import ActionGoal
from .._client import Client
from .._errors import ParameterError, RosBridgeError
from ._common import missing_line, open_robot, out, warn
from ._format import (
    UsageError,
    check_fields,
    dump_flow,
    dump_yaml,
    finite_or_none,
    parse_yaml_mapping,
    parse_yaml_value,
    plain,
)
from ._verb import Verb

__all__ = ["VERBS"]


# -- services --------------------------------------------------------------------------------


async def _services(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        for svc in robot.services:
            out(f"{svc.name}  [{svc.type}]" if ns.show_types else svc.name)
    return 0


def _build_services(p: argparse.ArgumentParser) -> None:
    p.add_argument("-t", "--show-types", action="store_true", help="print each service's type")


async def _call(ns: argparse.Namespace) -> int:
    request = parse_yaml_mapping(ns.request or "", "the request")
    async with open_robot(ns) as robot:
        svc = next((s for s in robot.services if s.name == ns.service), None)
        if svc is None and robot.services:
            warn(missing_line("service", ns.service, [s.name for s in robot.services]))
            return 1
        if svc is not None and svc.type:
            check_fields(robot, _part(svc.type, "Request"), request, "the request")
        reply = await robot.call_service(ns.service, request, timeout=ns.call_timeout)
    out(json.dumps(finite_or_none(plain(reply)), indent=2))
    return 0


def _part(service_type: str, which: str) -> str:
    return f"{service_type}_{which}"


def _build_call(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--call-timeout", type=float, default=10.0, metavar="S", help="seconds (default 10)"
    )


# -- parameters ------------------------------------------------------------------------------


def _print_values(values: Mapping[str, Any]) -> None:
    out(dump_yaml(plain(dict(values))).rstrip("\n"))


async def _param_list(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        values = await robot.list_parameters()
    for name in sorted(values):
        out(f"{name}: {_flow(values[name])}" if ns.values else name)
    return 0


def _flow(value: Any) -> str:
    return dump_flow(plain(value))


async def _param_get(ns: argparse.Namespace) -> int:
    reasons: dict[str, str] = {}
    async with open_robot(ns) as robot:
        try:
            values = await robot.get_parameters(ns.name)
        except ParameterError as exc:  # the found ones are printed, each missing one said
            values, reasons = exc.values, exc.reasons
    for name in ns.name:
        if name in values:
            out(f"{name}: {_flow(values[name])}")
    for name, why in reasons.items():
        warn(f"parameter {name!r}: {why}")
    return 1 if reasons else 0


async def _set_and_check(robot: Client, wanted: Mapping[str, Any]) -> int:
    """Set ``wanted``, print what the server reports, exit 1 unless every
    value was taken as given."""
    reasons: dict[str, str] = {}
    try:
        result = await robot.set_parameters(wanted)
    except ParameterError as exc:
        result, reasons = exc.values, exc.reasons
    for name, value in wanted.items():
        if name in reasons:
            warn(f"setting parameter {name} to {_flow(value)} failed: {reasons[name]}")
        else:
            out(f"Set parameter successful: {name}: {_flow(result.get(name))}")
    return 1 if reasons else 0


async def _param_set(ns: argparse.Namespace) -> int:
    value = parse_yaml_value(ns.value, f"the value of {ns.name}")
    async with open_robot(ns) as robot:
        return await _set_and_check(robot, {ns.name: value})


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


# -- action send -----------------------------------------------------------------------------


async def _action_send(ns: argparse.Namespace) -> int:
    import anyio

    goal = parse_yaml_mapping(ns.goal or "", "the goal")
    async with open_robot(ns) as robot:
        check_fields(robot, f"{ns.type}_Goal", goal, "the goal")
        out(f"Sending goal:\n{_indented(goal)}")
        async with (
            robot.send_action_goal(ns.action, ns.type, goal) as handle,
            anyio.create_task_group() as tg,
        ):

            async def feedback() -> None:
                async for values in handle.feedback:
                    if ns.feedback:
                        out(f"Feedback:\n{_indented(values)}")

            tg.start_soon(feedback)
            try:
                outcome = await handle.result()
            except anyio.get_cancelled_exc_class():
                await _cancel_goal(handle)  # Ctrl-C (or another signal)
                raise
            finally:
                tg.cancel_scope.cancel()
    out(f"Result:\n{_indented(outcome.result)}")
    out(f"Goal finished with status: {outcome.status.upper()}")
    return 0 if outcome.status == "succeeded" else 1


async def _cancel_goal(handle: ActionGoal) -> None:
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


VERBS = [
    Verb(("services",), "list services (-t: with types)", build=_build_services, run=_services),
    Verb(("service", "list"), "list services", build=_build_services, run=_services, hidden=True),
    Verb(
        ("call",), "call a service with a YAML request", ("SERVICE", "REQUEST?"), _build_call, _call
    ),
    Verb(
        ("service", "call"),
        "same as call",
        ("SERVICE", "REQUEST?"),
        _build_call,
        _call,
        hidden=True,
    ),
    Verb(("param", "list"), "list parameter names", (), _build_param_list, _param_list),
    Verb(
        ("param", "get"),
        "print parameters' values",
        ("NAME+",),
        None,
        _param_get,
        graph_names=False,
    ),
    Verb(
        ("param", "set"),
        "set a parameter (YAML value)",
        ("NAME", "VALUE"),
        None,
        _param_set,
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
