"""``rmb`` topic verbs, shaped like ``ros2 topic``: ``topics`` (``topic
list``), ``echo``, ``info`` and ``pub`` (``hz``, ``bw`` and ``delay`` are in
``_rate``)."""

from __future__ import annotations

import argparse
import logging
import math
from collections.abc import Mapping
from typing import Any

import anyio
import anyio.abc

from .._core._client import Client
from .._errors import NotConnected
from .._types import Message, Priority
from ..flow import Subscription
from ._common import check_type, missing_line, notice_if_missing, open_robot, out, warn
from ._format import (
    UsageError,
    check_fields,
    csv_line,
    dump_flow,
    dump_yaml,
    json_line,
    parse_yaml_mapping,
    plain,
    select_field,
)
from ._verb import Verb

__all__ = ["VERBS"]

# the verbs' help lines, as the index (_table) has them
_TOPICS = "list topics (-t types, -v publishers/subscribers, -c count, --json)"
_ECHO = "print a topic's messages as YAML (--json, --csv, --flow-style)"
_INFO = "the server (protocol, capabilities), or a topic (--json)"
_TOPIC_INFO = "a topic's type and counts (--json)"
_PUB = "publish a message (YAML) at 1 Hz until stopped (-r, --once, -t)"

_VELOCITY_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


# -- list --------------------------------------------------------------------------------


async def _graph_counts(robot: Client, topic: str) -> tuple[int | None, int | None]:
    """A topic's publisher and subscriber counts where the transport reports
    them (rosbridge, through /rosapi; Foxglove, from the server's connection
    graph); ``None`` where it does not, or the server cannot say."""
    if robot.protocol == "rosbridge":
        pubs = await _count(robot, "/rosapi/publishers", topic, "publishers")
        subs = await _count(robot, "/rosapi/subscribers", topic, "subscribers")
        return (int(pubs) if pubs.isdigit() else None), (int(subs) if subs.isdigit() else None)
    if robot.protocol == "foxglove-ws" and "connectionGraph" in robot.server_info.capabilities:
        from .._errors import RosBridgeError

        try:
            ends = await robot.topic_endpoints(topic)
        except RosBridgeError:
            return None, None
        return len(ends.publishers), len(ends.subscribers)
    return None, None


def _reports_counts(robot: Client) -> bool:
    """Whether :func:`_graph_counts` can know anything on this connection."""
    caps = robot.server_info.capabilities
    return robot.protocol == "rosbridge" or (
        robot.protocol == "foxglove-ws" and "connectionGraph" in caps
    )


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


async def _topics(ns: argparse.Namespace) -> int:
    """``topics`` / ``topic list`` as ``ros2 topic list``: names; ``-t``
    with types; ``-c`` the count; ``-v`` published and subscribed topics with
    their counts (where the transport knows them); ``--json`` one object per
    topic (``name``, ``type``, ``encoding``; with ``-v`` also ``publishers``
    and ``subscribers``, null when unknown) or ``{"count": N}``."""
    async with open_robot(ns) as robot:
        topics = sorted(robot.topics, key=lambda t: t.name)
        if ns.count_topics:
            out(json_line({"count": len(topics)}) if ns.json else str(len(topics)))
            return 0
        if not ns.verbose_listing:
            for t in topics:
                if ns.json:
                    out(json_line({"name": t.name, "type": t.schema_name, "encoding": t.encoding}))
                else:
                    out(f"{t.name}  [{t.schema_name}]" if ns.show_types else t.name)
            return 0
        counts = {t.name: await _graph_counts(robot, t.name) for t in topics}
    if ns.json:
        for t in topics:
            pubs, subs = counts[t.name]
            record = {"name": t.name, "type": t.schema_name, "encoding": t.encoding}
            out(json_line({**record, "publishers": pubs, "subscribers": subs}))
        return 0
    known = _reports_counts(robot)
    out("Published topics:")
    for t in topics:
        pubs = counts[t.name][0]
        if pubs is None:  # the transport lists the topics that have a publisher
            out(f" * {t.name} [{t.schema_name}]")
        elif pubs:
            out(f" * {t.name} [{t.schema_name}] {_plural(pubs, 'publisher')}")
    out("")
    out("Subscribed topics:")
    if not known:
        out(f" (not reported over {robot.protocol})")
    for t in topics:
        subs = counts[t.name][1]
        if subs:
            out(f" * {t.name} [{t.schema_name}] {_plural(subs, 'subscriber')}")
    out("")
    return 0


def _build_topics(p: argparse.ArgumentParser) -> None:
    p.add_argument("-t", "--show-types", action="store_true", help="print each topic's type")
    p.add_argument(
        "-v",
        "--verbose",
        dest="verbose_listing",
        action="store_true",
        help="ros2's verbose listing: published and subscribed topics, with types and counts",
    )
    p.add_argument(
        "-c", "--count-topics", action="store_true", help="print the number of topics only"
    )
    p.add_argument("--json", action="store_true", help="one JSON object per line")


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
    if ns.csv:
        out(csv_line(data))
    elif ns.flow_style:
        out(dump_flow(data) + "\n---")
    else:
        out(dump_yaml(data) + "---")


async def _echo(ns: argparse.Namespace) -> int:
    limit = 1 if ns.once else ns.count
    if limit < 0:
        raise UsageError(f"--count must be 0 (until stopped) or more, got {limit}")
    seen = [0]
    async with open_robot(ns) as robot:
        schema = await _echo_schema(robot, ns.topic, ns.type)
        async with (
            robot.subscribe(ns.topic, max_hz=ns.max_hz, schema=schema) as sub,
            anyio.create_task_group() as tg,
        ):
            await _echo_loop(robot, ns, sub, tg, limit, seen)
    return 0


async def _echo_schema(robot: Client, topic: str, given: str | None) -> str | None:
    """ros2's ``echo TOPIC TYPE``: the type must be the one the robot lists
    for the topic (checked once the robot lists it, giving discovery a
    second); used as the schema when the robot does not say."""
    if given is None:
        return None
    with anyio.move_on_after(1.0):
        async for topics in robot.watch_topics():
            if any(t.name == topic for t in topics):
                break
    known = next((t.schema_name for t in robot.topics if t.name == topic), None)
    check_type("msg", topic, given, known)
    return None if known else given


async def _echo_loop(
    robot: Client,
    ns: argparse.Namespace,
    sub: Subscription,
    tg: anyio.abc.TaskGroup,
    limit: int,
    seen: list[int],
) -> None:
    tg.start_soon(notice_if_missing, robot, ns.topic, seen)
    async for msg in sub:
        seen[0] += 1
        _print_message(msg, ns)
        if limit and seen[0] >= limit:
            break
    tg.cancel_scope.cancel()


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
    style = p.add_mutually_exclusive_group()
    style.add_argument(
        "--json",
        action="store_true",
        help="one JSON object per line (full arrays; NaN and infinities as null)",
    )
    style.add_argument(
        "--csv", action="store_true", help="one line of comma-separated values per message"
    )
    style.add_argument(
        "--flow-style", action="store_true", help="each message as one line of flow-style YAML"
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
    # an instance of rosapi's response class where the bridge described it, else a dict
    names = reply.get(key) if isinstance(reply, Mapping) else getattr(reply, key, None)
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
            pubs_n, subs_n = await _graph_counts(robot, ns.topic)
            record = {"topic": ns.topic, "type": topic.schema_name, "encoding": topic.encoding}
            out(json_line({**record, "publishers": pubs_n, "subscriptions": subs_n}))
            return 0
        out(f"Type: {topic.schema_name}")
        if topic.encoding:
            out(f"Encoding: {topic.encoding}")
        if _reports_counts(robot):
            counts = await _graph_counts(robot, ns.topic)
            pubs, subs = ("unknown" if n is None else str(n) for n in counts)
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
        check_fields(robot, ns.type, data, f"publish {ns.topic}")
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
                if not logging.getLogger("ros_mobile_bridge").isEnabledFor(logging.WARNING):
                    # else the library's "connection lost" line already said it: one line
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
    Verb(("topics",), _TOPICS, build=_build_topics, run=_topics),
    Verb(("topic", "list"), _TOPICS, build=_build_topics, run=_topics, hidden=True),
    Verb(("echo",), _ECHO, ("TOPIC", "TYPE?"), _build_echo, _echo),
    Verb(("topic", "echo"), _ECHO, ("TOPIC", "TYPE?"), _build_echo, _echo, hidden=True),
    Verb(("info",), _INFO, ("TOPIC?",), _build_info, _info),
    Verb(("topic", "info"), _TOPIC_INFO, ("TOPIC",), _build_info, _info, hidden=True),
    Verb(("pub",), _PUB, ("TOPIC", "TYPE", "DATA?"), _build_pub, _pub),
    Verb(("topic", "pub"), _PUB, ("TOPIC", "TYPE", "DATA?"), _build_pub, _pub, hidden=True),
]
