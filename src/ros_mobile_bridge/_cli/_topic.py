"""``rmb`` topic verbs, shaped like ``ros2 topic``: ``topics`` (``topic
list``), ``echo``, ``info`` and ``pub`` (``hz``, ``bw`` and ``delay`` are in
``_rate``)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Mapping
from typing import Any

import anyio

from .._client import Client
from .._errors import NotConnected
from .._types import Message, Priority
from ._common import missing_line, notice_if_missing, open_robot, out, warn
from ._format import (
    UsageError,
    check_fields,
    dump_flow,
    dump_yaml,
    json_line,
    parse_yaml_mapping,
    plain,
    select_field,
)
from ._verb import Verb

__all__ = ["VERBS"]

_VELOCITY_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


# -- list --------------------------------------------------------------------------------


async def _topics(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        for topic in robot.topics:
            out(f"{topic.name}  [{topic.schema_name}]" if ns.show_types else topic.name)
    return 0


def _build_topics(p: argparse.ArgumentParser) -> None:
    p.add_argument("-t", "--show-types", action="store_true", help="print each topic's type")


# -- echo --------------------------------------------------------------------------------


def message_info(msg: Message) -> dict[str, Any]:
    """The transport's message info: when it arrived, the wire's timestamp
    (Foxglove's log time, rmw_zenoh's source timestamp; None over
    rosbridge), the publisher's sequence number (Zenoh; else None) and the
    payload's size."""
    return {
        "receive_time_ns": msg.receive_time_ns,
        "log_time_ns": msg.log_time_ns,
        "sequence": msg.sequence,
        "byte_size": msg.byte_size,
    }


def _info_line(msg: Message) -> str:
    return "# " + ", ".join(f"{k}: {v}" for k, v in message_info(msg).items() if v is not None)


def _print_message(msg: Message, ns: argparse.Namespace) -> None:
    if msg.decode_error:
        if ns.json:
            record = {"topic": msg.topic, "schema": msg.schema_name, **message_info(msg)}
            out(json_line({**record, "data": None, "decode_error": msg.decode_error}))
        else:
            info = f"{_info_line(msg)}\n" if ns.info else ""
            out(f"{info}# not decoded ({msg.decode_error}): {msg.byte_size} bytes\n---")
        return
    value: Any = msg.data
    if ns.field:
        value = select_field(value, ns.field)
    if ns.json:
        data = plain(value, no_arr=ns.no_arr, no_str=ns.no_str)
        out(
            json_line(
                {"topic": msg.topic, "schema": msg.schema_name, **message_info(msg), "data": data}
            )
        )
        return
    truncate = None if ns.full or ns.truncate_length <= 0 else ns.truncate_length
    data = plain(value, truncate=truncate, no_arr=ns.no_arr, no_str=ns.no_str)
    if ns.info:
        out(_info_line(msg))
    out(dump_yaml(data) + "---")


async def _echo(ns: argparse.Namespace) -> int:
    limit = 1 if ns.once else ns.count
    if limit < 0:
        raise UsageError(f"--count must be 0 (until stopped) or more, got {limit}")
    seen = [0]
    async with (
        open_robot(ns) as robot,
        robot.subscribe(ns.topic, max_hz=ns.max_hz) as sub,
        anyio.create_task_group() as tg,
    ):
        tg.start_soon(notice_if_missing, robot, ns.topic, seen)
        async for msg in sub:
            seen[0] += 1
            _print_message(msg, ns)
            if limit and seen[0] >= limit:
                break
        tg.cancel_scope.cancel()
    return 0


def _build_echo(p: argparse.ArgumentParser) -> None:
    p.add_argument("--once", action="store_true", help="print one message and exit")
    p.add_argument(
        "-n", "--count", type=int, default=0, help="exit after N messages (default: until stopped)"
    )
    p.add_argument("--field", metavar="A.B", help="print only this field (a.b.c; numbers index)")
    p.add_argument("--no-arr", action="store_true", help="print array fields as their length")
    p.add_argument("--no-str", action="store_true", help="print string fields as their length")
    p.add_argument(
        "--truncate-length",
        type=int,
        default=128,
        metavar="N",
        help="cut arrays and strings after N items (default 128, 0: never)",
    )
    p.add_argument("--full", action="store_true", help="never cut (same as --truncate-length 0)")
    p.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per line (full arrays; NaN and infinities as null)",
    )
    p.add_argument("--max-hz", type=float, default=None, help="deliver at most this rate")
    p.add_argument(
        "--info",
        action="store_true",
        help="print each message's info first: receive time, the wire's timestamp (Foxglove "
        "log time, Zenoh source time), sequence number (Zenoh), size (--json: always)",
    )


# -- info ----------------------------------------------------------------------------------


async def _known_topic(robot: Client, topic: str, wait: float = 1.0) -> bool:
    """Whether the robot lists ``topic``, giving discovery ``wait`` seconds."""
    with anyio.move_on_after(wait):
        async for topics in robot.watch_topics():
            if any(t.name == topic for t in topics):
                return True
    return False


async def _count(robot: Client, service: str, topic: str, key: str) -> str:
    from .._errors import RosBridgeError

    try:
        reply = await robot.call_service(service, {"topic": topic}, timeout=5)
    except RosBridgeError:
        return "unknown"
    names = reply.get(key) if isinstance(reply, Mapping) else None
    return str(len(names)) if isinstance(names, list) else "unknown"


def _server_record(robot: Client, url: str | None) -> dict[str, Any]:
    info = robot.server_info
    return {
        "server": info.name,
        "url": url,
        "protocol": robot.protocol,
        "subprotocol": info.subprotocol,
        "capabilities": list(info.capabilities),
        "encodings": list(info.supported_encodings),
        "session": info.session_id,
        "metadata": dict(info.metadata),
        "topics": len(robot.topics),
        "services": len(robot.services),
    }


async def _counts(robot: Client, topic: str) -> tuple[int | None, int | None]:
    """Publisher and subscription counts where the transport reports them
    (rosbridge), else None."""
    if robot.protocol != "rosbridge":
        return None, None
    found = []
    for service, key in (
        ("/rosapi/publishers", "publishers"),
        ("/rosapi/subscribers", "subscribers"),
    ):
        text = await _count(robot, service, topic, key)
        found.append(int(text) if text.isdigit() else None)
    return found[0], found[1]


def _build_info(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="one JSON object instead of text")


async def _info(ns: argparse.Namespace) -> int:
    async with open_robot(ns) as robot:
        if ns.topic is None and ns.json:
            out(json_line(_server_record(robot, ns.url)))
            return 0
        if ns.topic is None:
            info = robot.server_info
            sub = f", subprotocol {info.subprotocol}" if info.subprotocol else ""
            out(f"server: {info.name}")
            out(f"url: {ns.url}")
            out(f"protocol: {robot.protocol}{sub}")
            out(f"capabilities: {', '.join(info.capabilities) or '(none listed)'}")
            if info.supported_encodings:
                out(f"encodings: {', '.join(info.supported_encodings)}")
            if info.session_id:
                out(f"session: {info.session_id}")
            for key, value in sorted(info.metadata.items()):
                out(f"metadata: {key}={value}")
            out(f"topics: {len(robot.topics)}")
            out(f"services: {len(robot.services)}")
            return 0
        if not await _known_topic(robot, ns.topic):
            warn(missing_line("topic", ns.topic, [t.name for t in robot.topics]))
            return 1
        topic = next(t for t in robot.topics if t.name == ns.topic)
        if ns.json:
            pubs_n, subs_n = await _counts(robot, ns.topic)
            record = {"topic": ns.topic, "type": topic.schema_name, "encoding": topic.encoding}
            out(json_line({**record, "publishers": pubs_n, "subscriptions": subs_n}))
            return 0
        out(f"Type: {topic.schema_name}")
        if topic.encoding:
            out(f"Encoding: {topic.encoding}")
        if robot.protocol == "rosbridge":
            pubs = await _count(robot, "/rosapi/publishers", ns.topic, "publishers")
            subs = await _count(robot, "/rosapi/subscribers", ns.topic, "subscribers")
        else:
            pubs = subs = f"unknown ({robot.protocol} does not report it)"
        out(f"Publisher count: {pubs}")
        out(f"Subscription count: {subs}")
    return 0


# -- pub -------------------------------------------------------------------------------------


def _moving(value: Any) -> bool:
    if isinstance(value, Mapping):
        return any(_moving(v) for k, v in value.items() if k != "header")
    if isinstance(value, list):
        return any(_moving(v) for v in value)
    return isinstance(value, int | float) and not isinstance(value, bool) and value != 0


async def _pub(ns: argparse.Namespace) -> int:
    data = parse_yaml_mapping(ns.data or "", "the message")
    rate = ns.rate
    if not (rate > 0) or math.isinf(rate):
        raise UsageError(f"-r/--rate must be a positive number of Hz, got {rate!r}")
    times = 1 if ns.once else ns.times
    if times < 0:
        raise UsageError(f"-t/--times must be 0 (until stopped) or more, got {times}")
    if ns.print_nth < 0:
        raise UsageError(f"-p/--print must be 0 (never) or more, got {ns.print_nth}")
    velocity = ns.topic.endswith("cmd_vel") or ns.type in _VELOCITY_TYPES
    priority: Priority = "control" if ns.control else "data"
    shown = dump_flow(data)
    async with open_robot(ns) as robot:
        check_fields(robot, ns.type, data, "the message")
        if velocity and ns.no_velocity_check and ns.type not in _VELOCITY_TYPES:
            # (without --no-velocity-check the library refuses such a publish)
            warn(
                f"warning: {ns.type} on {ns.topic} gets no stop command when rmb ends (only "
                "Twist and TwistStamped get the teardown's zero Twist): the robot keeps this "
                "command until its own watchdog stops it."
            )
        elif times == 1 and velocity and _moving(data):
            warn(
                f"note: one command to {ns.topic}, and the teardown's zero Twist right behind "
                "it: the robot will not move. Use -r 10 to drive until Ctrl-C (the zero Twist "
                "follows then)."
            )
        sent = 0
        period = 1.0 / rate
        next_at = anyio.current_time()
        while True:
            try:
                await robot.publish(
                    ns.topic,
                    ns.type,
                    data,
                    priority=priority,
                    check_velocity=not ns.no_velocity_check,
                )
            except NotConnected:
                # the connection is down: wait for the client to bring it
                # back (its reconnect policy), so the run goes on and the
                # teardown can still send the zero Twist; a client that
                # gives up ends the command (exit 1)
                if robot.status != "reconnecting":
                    raise
                warn(f"connection lost: waiting for it to come back ({robot.last_error})")
                await _until_connected(robot)
                warn("connected again: publishing")
                next_at = anyio.current_time()
                continue
            sent += 1
            if ns.print_nth and sent % ns.print_nth == 0:
                out(f"publishing #{sent}: {shown}")
            if times and sent >= times:
                break
            # on the rate's grid; after a stall, on from now (no burst to catch up)
            next_at = max(next_at + period, anyio.current_time())
            await anyio.sleep_until(next_at)
    return 0


async def _until_connected(robot: Client) -> None:
    """Return once ``robot`` is connected again; ``NotConnected`` when it
    gives up (or closes) instead."""
    async for status in robot.watch_status():
        if status == "connected":
            return
        if status in ("closed", "error"):
            break
    raise NotConnected(f"the connection did not come back: {robot.last_error}")


def _build_pub(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "-r", "--rate", type=float, default=1.0, metavar="HZ", help="publishing rate (default 1)"
    )
    p.add_argument("-1", "--once", action="store_true", help="publish one message and exit")
    p.add_argument(
        "-t",
        "--times",
        type=int,
        default=0,
        metavar="N",
        help="publish N messages and exit (default 0: until stopped)",
    )
    p.add_argument("-n", dest="times", type=int, help=argparse.SUPPRESS)  # rmb 0.1's spelling
    p.add_argument(
        "-p",
        "--print",
        dest="print_nth",
        type=int,
        default=1,
        metavar="N",
        help="print every Nth message sent (default 1, 0: none)",
    )
    p.add_argument("--control", action="store_true", help="control priority (ahead of data)")
    p.add_argument(
        "--no-velocity-check",
        action="store_true",
        help="allow a type other than Twist/TwistStamped on a velocity topic (*cmd_vel); "
        "such a type gets no stop command when rmb ends",
    )


VERBS = [
    Verb(("topics",), "list topics (-t: with types)", build=_build_topics, run=_topics),
    Verb(("topic", "list"), "list topics (-t: with types)", build=_build_topics, run=_topics),
    Verb(("echo",), "print a topic's messages as YAML (or --json)", ("TOPIC",), _build_echo, _echo),
    Verb(("topic", "echo"), "same as echo", ("TOPIC",), _build_echo, _echo, hidden=True),
    Verb(
        ("info",),
        "the server (protocol, capabilities), or a topic",
        ("TOPIC?",),
        _build_info,
        _info,
    ),
    Verb(
        ("topic", "info"), "a topic's type and counts", ("TOPIC",), _build_info, _info, hidden=True
    ),
    Verb(
        ("pub",),
        "publish a message (YAML) at 1 Hz until stopped (-r, --once, -t)",
        ("TOPIC", "TYPE", "DATA?"),
        _build_pub,
        _pub,
    ),
    Verb(
        ("topic", "pub"), "same as pub", ("TOPIC", "TYPE", "DATA?"), _build_pub, _pub, hidden=True
    ),
]
