"""The ``rmb`` command line, in the shape of ``ros2 topic`` / ``ros2 service``.

``rmb demo`` is the main job: it starts the embedded demo robot (served by
the official Foxglove SDK server on 127.0.0.1), drives it in a circle with
this library while printing a live readout, and leaves with the zero Twist,
showing that the robot received it last."""

from __future__ import annotations

import argparse
import json
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import anyio

from . import _connect
from ._errors import RosBridgeError
from ._options import ClientOptions
from ._signals import cancel_on_signals
from ._types import Message, Priority

__all__ = ["main"]


# -- output helpers -------------------------------------------------------------


def to_jsonable(value: Any, *, full: bool = True, limit: int = 16) -> Any:
    """A JSON-serialisable copy of a decoded message. numpy arrays, bytes and
    memoryviews become lists (or, with ``full=False``, a short summary when
    longer than ``limit``)."""
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v, full=full, limit=limit) for k, v in value.items()}
    if isinstance(value, list | tuple):
        if not full and len(value) > limit:
            return [to_jsonable(v, full=full, limit=limit) for v in value[:limit]] + [
                f"... {len(value)} items"
            ]
        return [to_jsonable(v, full=full, limit=limit) for v in value]
    if isinstance(value, bytes | bytearray | memoryview):
        raw = bytes(value)
        if not full and len(raw) > limit:
            return f"<{len(raw)} bytes>"
        return list(raw)
    tolist = getattr(value, "tolist", None)
    if callable(tolist):
        shape = getattr(value, "shape", ())
        size = getattr(value, "size", 0)
        if not full and size > limit:
            return f"<{getattr(value, 'dtype', 'array')}{list(shape)}>"
        return tolist()
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def _print_yaml(value: Any, indent: int = 0) -> None:
    pad = "  " * indent
    if isinstance(value, dict):
        for key, item in value.items():
            if isinstance(item, dict):
                print(f"{pad}{key}:")
                _print_yaml(item, indent + 1)
            else:
                text = repr(item) if isinstance(item, str) else json.dumps(item)
                print(f"{pad}{key}: {text}")
    else:
        print(f"{pad}{value!r}")


def _parse_json_arg(text: str, what: str) -> dict[str, Any]:
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SystemExit(f"rmb: {what} is not valid JSON: {exc}") from None
    if not isinstance(value, dict):
        raise SystemExit(f"rmb: {what} must be a JSON object, got {type(value).__name__}")
    return value


def _options(args: argparse.Namespace, **extra: Any) -> ClientOptions:
    return ClientOptions(connect_timeout=args.timeout, **extra)


# -- commands ---------------------------------------------------------------------


async def _topics(args: argparse.Namespace) -> int:
    async with _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot:
        for topic in robot.topics:
            print(f"{topic.name}  [{topic.schema_name}]" if args.show_types else topic.name)
    return 0


async def _services(args: argparse.Namespace) -> int:
    async with _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot:
        for svc in robot.services:
            print(f"{svc.name}  [{svc.type}]" if args.show_types else svc.name)
    return 0


async def _echo(args: argparse.Namespace) -> int:
    count = 0
    async with (
        _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot,
        robot.subscribe(args.topic, max_hz=args.max_hz) as sub,
    ):
        async for msg in sub:
            _print_message(msg, as_json=args.json, full=args.full)
            count += 1
            if args.count and count >= args.count:
                break
    return 0


def _print_message(msg: Message, *, as_json: bool, full: bool) -> None:
    data = to_jsonable(msg.data, full=as_json or full)
    if as_json:
        record = {
            "topic": msg.topic,
            "schema": msg.schema_name,
            "log_time_ns": msg.log_time_ns,
            "receive_time_ns": msg.receive_time_ns,
            "data": data,
        }
        print(json.dumps(record), flush=True)
    else:
        if msg.decode_error:
            print(f"# not decoded ({msg.decode_error}): {msg.byte_size} bytes")
        else:
            _print_yaml(data)
        print("---", flush=True)


async def _pub(args: argparse.Namespace) -> int:
    data = _parse_json_arg(args.data, "DATA")
    priority: Priority = "control" if args.control else "data"
    rate = 1.0 if args.rate is None else args.rate
    if not rate > 0 or math.isinf(rate):
        raise ValueError(f"--rate must be a positive number of Hz, got {rate!r}")
    # -r without -n publishes until stopped (a signal), like ``ros2 topic pub``
    count = args.count if args.count is not None else (0 if args.rate is not None else 1)
    if count < 0:
        raise ValueError(f"--count must be 0 (until stopped) or more, got {count}")
    async with _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot:
        sent = 0
        while True:
            await robot.publish(
                args.topic,
                args.type,
                data,
                priority=priority,
                check_velocity=not args.no_velocity_check,
            )
            sent += 1
            print(f"publishing #{sent}: {json.dumps(data)}", flush=True)
            if count and sent >= count:
                break
            await anyio.sleep(1.0 / rate)
    return 0


async def _call(args: argparse.Namespace) -> int:
    request = _parse_json_arg(args.request, "REQUEST") if args.request else {}
    async with _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot:
        reply = await robot.call_service(args.service, request, timeout=args.call_timeout)
    print(json.dumps(to_jsonable(reply), indent=2))
    return 0


async def _params(args: argparse.Namespace) -> int:
    async with _connect.connect(args.url, protocol=args.protocol, options=_options(args)) as robot:
        if args.set:
            values: dict[str, Any] = {}
            for item in args.set:
                name, sep, text = item.partition("=")
                if not sep:
                    raise SystemExit(f"rmb: --set wants NAME=VALUE (JSON value), got {item!r}")
                try:
                    values[name] = json.loads(text)
                except json.JSONDecodeError:
                    values[name] = text
            result = await robot.set_parameters(values)
        elif args.names:
            result = await robot.get_parameters(args.names)
        else:
            result = await robot.list_parameters()
    print(json.dumps(to_jsonable(result), indent=2, sort_keys=True))
    return 0


# -- the demo ---------------------------------------------------------------------


class _Rates:
    def __init__(self) -> None:
        self.counts: dict[str, int] = {}
        self.start = time.monotonic()

    def hit(self, topic: str) -> None:
        self.counts[topic] = self.counts.get(topic, 0) + 1

    def line(self) -> str:
        elapsed = max(time.monotonic() - self.start, 1e-9)
        return "  ".join(f"{t} {n / elapsed:4.1f}Hz" for t, n in sorted(self.counts.items()))


async def _drive_demo(url: str, seconds: float, out: Callable[[str], None]) -> None:
    """The client session of ``rmb demo`` against the robot at ``url``."""
    options = ClientOptions(connect_timeout=5.0)
    async with _connect.connect(url, options=options) as robot:
        out(
            f"connected to {robot.server_info.name!r} over {robot.protocol} ({robot.server_info.subprotocol})"
        )
        out("topics:   " + ", ".join(f"{t.name} [{t.schema_name}]" for t in robot.topics))
        out("services: " + ", ".join(f"{s.name} [{s.type}]" for s in robot.services))
        params = await robot.list_parameters()
        out(f"parameters: {json.dumps(params, sort_keys=True)}")
        reply = await robot.call_service("/set_led", {"data": True}, timeout=5)
        out(f"call /set_led {{data: true}} -> {reply}")
        await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")

        rates = _Rates()
        state: dict[str, Any] = {}

        async def follow(topic: str, max_hz: float | None) -> None:
            async with robot.subscribe(topic, max_hz=max_hz, dispatch="latest") as sub:
                async for msg in sub:
                    rates.hit(topic)
                    state[topic] = msg.data

        async with anyio.create_task_group() as tg:
            for topic, cap in (
                ("/odom", None),
                ("/battery", None),
                ("/camera/image/compressed", None),
                ("/status", None),
            ):
                tg.start_soon(follow, topic, cap)
            out(
                f"driving in a circle for {seconds:g} s (linear.x 0.4 m/s, angular.z 0.8 rad/s) ..."
            )
            deadline = time.monotonic() + seconds
            next_print = 0.0
            while time.monotonic() < deadline:
                await robot.publish(
                    "/cmd_vel",
                    "geometry_msgs/msg/Twist",
                    {"linear": {"x": 0.4}, "angular": {"z": 0.8}},
                    priority="control",
                )
                now = time.monotonic()
                if now >= next_print:
                    next_print = now + 0.5
                    out(_readout(state, rates))
                await anyio.sleep(0.1)
            tg.cancel_scope.cancel()
        out("leaving the session: the teardown sends a zero Twist to /cmd_vel, then closes")


def _readout(state: Mapping[str, Any], rates: _Rates) -> str:
    odom = state.get("/odom")
    pose = "pose: waiting for /odom"
    if isinstance(odom, Mapping):
        p = odom["pose"]["pose"]
        q = p["orientation"]
        yaw = math.atan2(
            2 * (q["w"] * q["z"] + q["x"] * q["y"]), 1 - 2 * (q["y"] ** 2 + q["z"] ** 2)
        )
        pose = f"pose x={p['position']['x']:+.2f} y={p['position']['y']:+.2f} yaw={math.degrees(yaw):+6.1f}deg"
    battery = state.get("/battery")
    batt = f"battery {battery['percentage'] * 100:.1f}%" if isinstance(battery, Mapping) else ""
    return f"  {pose}  {batt}  | {rates.line()}"


async def _serve_until_signalled(url: str) -> None:
    # said once the signals are ours, so a supervisor may stop us from here on
    print(f"demo robot serving Foxglove WebSocket on {url} (Ctrl-C to stop)", flush=True)
    await anyio.sleep_forever()


def _demo(args: argparse.Namespace) -> int:
    try:
        from .demo import DemoRobot
    except ImportError as exc:  # the Foxglove SDK is the optional [demo] extra
        print(
            f"rmb demo needs the demo extra: pip install 'ros-mobile-bridge[demo]' ({exc})",
            file=sys.stderr,
        )
        return 2
    robot = DemoRobot(port=args.port)
    robot.start()
    try:
        if args.serve:
            return _run_signalled(_serve_until_signalled, robot.url, backend=args.backend)
        print(f"demo robot started on {robot.url}", flush=True)
        code = _run_signalled(
            _drive_demo,
            robot.url,
            args.seconds,
            lambda s: print(s, flush=True),
            backend=args.backend,
        )
        if code:
            return code
        # the zero Twist is the last command the robot received
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline:
            log = robot.received_cmd_vel()
            if log and log[-1].linear_x == 0.0 and log[-1].angular_z == 0.0:
                break
            time.sleep(0.02)
        log = robot.received_cmd_vel()
        if not log:
            print("FAIL: the robot received no velocity command", file=sys.stderr)
            return 1
        last = log[-1]
        moving = sum(1 for c in log if c.linear_x or c.angular_z)
        print(
            f"robot received {len(log)} velocity commands ({moving} moving); "
            f"the last one: linear.x={last.linear_x} angular.z={last.angular_z} ({last.encoding})"
        )
        if last.linear_x == 0.0 and last.angular_z == 0.0:
            x, y, _ = robot.pose
            print(f"OK: the zero Twist arrived last; the robot stopped at x={x:+.2f} y={y:+.2f}")
            return 0
        print("FAIL: the last command the robot received was not a zero Twist", file=sys.stderr)
        return 1
    finally:
        robot.stop()


# -- entry point ----------------------------------------------------------------------


def _run_signalled(fn: Callable[..., Any], *args: Any, backend: str) -> int:
    """Run ``fn(*args)`` on ``backend``, cancelled by SIGINT, SIGTERM or
    SIGHUP (so every ``connect()`` block runs its teardown); the exit status
    is 128 + signal then, else what ``fn`` returned (None: 0). A second
    signal ends the process at once."""

    async def signalled() -> int:
        code: Any = 0
        async with cancel_on_signals() as stop:
            code = await fn(*args)
        if stop.exit_code is not None:
            return stop.exit_code
        return int(code or 0)

    return int(anyio.run(signalled, backend=backend))


def _stdout_closed() -> int:
    """stdout's reader went away (``rmb echo ... | head -1``): the teardown
    already ran as the error left the ``connect()`` block. Point stdout at
    the null device so the interpreter's last flush cannot fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass
    return 128 + signal.SIGPIPE if hasattr(signal, "SIGPIPE") else 1


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rmb", description="ROS 2 robots from Python, without ROS."
    )
    parser.add_argument(
        "--backend",
        choices=("asyncio", "trio"),
        default="asyncio",
        help="event loop (default asyncio)",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="run the embedded demo robot and drive it (the main job)")
    demo.add_argument("--serve", action="store_true", help="only serve the robot, for other tools")
    demo.add_argument(
        "--port", type=int, default=0, help="port for the robot's server (default: any free)"
    )
    demo.add_argument("--seconds", type=float, default=4.0, help="how long to drive (default 4)")
    demo.set_defaults(run=_demo)

    def common(p: argparse.ArgumentParser) -> None:
        p.add_argument("url", help="robot: host, host:port, ws://host:port, wss://...")
        p.add_argument(
            "--protocol", default="auto", choices=("auto", "foxglove-ws", "rosbridge", "zenoh")
        )
        p.add_argument("--timeout", type=float, default=10.0, help="connect timeout, seconds")

    p = sub.add_parser("topics", help="list topics")
    common(p)
    p.add_argument("-t", "--show-types", action="store_true")
    p.set_defaults(run_async=_topics)

    p = sub.add_parser("services", help="list services")
    common(p)
    p.add_argument("-t", "--show-types", action="store_true")
    p.set_defaults(run_async=_services)

    p = sub.add_parser("echo", help="print messages of a topic")
    common(p)
    p.add_argument("topic")
    p.add_argument("--max-hz", type=float, default=None)
    p.add_argument("-n", "--count", type=int, default=0, help="stop after N messages")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.add_argument("--full", action="store_true", help="print long arrays in full")
    p.set_defaults(run_async=_echo)

    p = sub.add_parser("pub", help="publish a message")
    common(p)
    p.add_argument("topic")
    p.add_argument("type", help="e.g. geometry_msgs/msg/Twist")
    p.add_argument("data", help='JSON object, e.g. \'{"linear": {"x": 0.1}}\'')
    p.add_argument(
        "-r", "--rate", type=float, default=None, help="Hz (default 1); alone: until stopped"
    )
    p.add_argument(
        "-n",
        "--count",
        type=int,
        default=None,
        help="messages to send, 0: until stopped (default 1, or 0 with --rate)",
    )
    p.add_argument("--control", action="store_true", help="control priority")
    p.add_argument(
        "--no-velocity-check",
        action="store_true",
        help="allow a type other than Twist/TwistStamped on a velocity topic (*cmd_vel)",
    )
    p.set_defaults(run_async=_pub)

    p = sub.add_parser("call", help="call a service")
    common(p)
    p.add_argument("service")
    p.add_argument("request", nargs="?", default="", help="JSON object")
    p.add_argument("--call-timeout", type=float, default=10.0)
    p.set_defaults(run_async=_call)

    p = sub.add_parser("params", help="list, get or set parameters")
    common(p)
    p.add_argument("names", nargs="*")
    p.add_argument("--set", action="append", metavar="NAME=VALUE")
    p.set_defaults(run_async=_params)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``rmb`` command line; returns the exit status."""
    args = _parser().parse_args(argv)
    try:
        if hasattr(args, "run"):
            return int(args.run(args))
        return _run_signalled(args.run_async, args, backend=args.backend)
    except BrokenPipeError:
        return _stdout_closed()
    except RosBridgeError as exc:
        print(f"rmb: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1
    except (ValueError, TypeError) as exc:
        print(f"rmb: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130
