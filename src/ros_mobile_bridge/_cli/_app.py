"""The ``rmb`` entry point: global options, the verb table, where the robot's
address comes from, and how every failure becomes one line and an exit code.

Exit codes: 0 done; 1 a runtime failure (refused connection, a service that
failed, nothing found or set); 2 a usage mistake (bad option, bad YAML, a
field the type does not have); 128 + signal when stopped by SIGINT (130),
SIGTERM (143) or SIGHUP (129), every teardown having run; 141 when stdout's
reader went away (``rmb echo ... | head -1``)."""

from __future__ import annotations

import argparse
import importlib
import logging
import os
import re
import signal
import sys
import traceback
from collections.abc import Sequence
from typing import Any

from .._errors import RosBridgeError
from .._version import __version__
from ._format import UsageError
from ._verb import Verb, run_signalled

if sys.version_info < (3, 11):  # pragma: no cover - the backport anyio installs there
    from exceptiongroup import BaseExceptionGroup

__all__ = ["ENV_URL", "Verb", "main"]

ENV_URL = "RMB_URL"
"""The environment variable holding the robot's address when none is given."""


def _verbs() -> list[Verb]:
    from . import _demo, _interface, _record, _ros, _topic  # they import _verb, never this module

    return [*_demo.VERBS, *_topic.VERBS, *_ros.VERBS, *_interface.VERBS, *_record.VERBS]


# -- parsing -------------------------------------------------------------------------------


def _common_options(p: argparse.ArgumentParser, *, default: Any) -> None:
    """The options every verb takes, before or after the verb's name. In a
    verb's parser they default to ``argparse.SUPPRESS`` so that the global
    value stays unless repeated there."""
    d = (lambda v: argparse.SUPPRESS) if default is argparse.SUPPRESS else (lambda v: v)
    p.add_argument(
        "-u",
        "--url",
        default=d(None),
        metavar="URL",
        help=f"the robot: host, host:port, ws://host:port, wss://... (default: ${ENV_URL})",
    )
    p.add_argument(
        "--protocol",
        default=d("auto"),
        choices=("auto", "foxglove-ws", "rosbridge", "zenoh"),
        help="wire protocol (default auto: detected from the handshake)",
    )
    p.add_argument(
        "--timeout", type=float, default=d(10.0), metavar="S", help="connect timeout (default 10)"
    )
    p.add_argument(
        "--backend",
        choices=("asyncio", "trio"),
        default=d("asyncio"),
        help="event loop (default asyncio)",
    )
    p.add_argument(
        "-v",
        "--verbose",
        action="count",
        default=d(0),
        help="log more (-v info, -vv debug) and show tracebacks",
    )
    p.add_argument(
        "--log-level",
        default=d(None),
        type=str.upper,
        choices=("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"),
        help="log level of the library's logger (default WARNING)",
    )


def _top_parser(verbs: list[Verb]) -> argparse.ArgumentParser:
    names = sorted({v.path[0] for v in verbs if not v.hidden})
    lines = []
    for v in verbs:
        if not v.hidden:
            lines.append(f"  {' '.join(v.path):<16} {v.help}")
    parser = argparse.ArgumentParser(
        prog="rmb",
        usage="rmb [options] COMMAND [URL] [ARGS ...]",
        description="ROS 2 robots from Python, without ROS: the ros2 command's verbs over "
        "Foxglove WebSocket, rosbridge and Zenoh.",
        epilog="commands:\n"
        + "\n".join(lines)
        + f"\n\nThe robot's address: -u URL, else a first argument that reads as one, "
        f"else ${ENV_URL}.\n'rmb COMMAND --help' for a command's options. Exit codes: 0 ok, "
        "1 runtime failure, 2 usage mistake, 130 Ctrl-C (SIGINT), 143 SIGTERM, 129 SIGHUP, "
        "141 stdout closed.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--version", action="version", version=f"rmb (ros-mobile-bridge) {__version__}"
    )
    _common_options(parser, default=None)
    parser.add_argument("command", metavar="COMMAND", nargs="?", help=", ".join(names))
    parser.add_argument("rest", nargs=argparse.REMAINDER, help=argparse.SUPPRESS)
    return parser


def _verb_parser(verb: Verb) -> argparse.ArgumentParser:
    prog = "rmb " + " ".join(verb.path)
    needs_url = verb.run is not None
    parser = argparse.ArgumentParser(
        prog=prog,
        usage=f"%(prog)s [options] {'[URL] ' if needs_url else ''}{verb.usage_args}".rstrip(),
        description=verb.help,
    )
    if needs_url:
        _common_options(parser, default=argparse.SUPPRESS)
    else:
        parser.add_argument("--backend", choices=("asyncio", "trio"), default=argparse.SUPPRESS)
    if verb.build is not None:
        verb.build(parser)
    parser.add_argument("args", nargs="*", help=argparse.SUPPRESS)
    return parser


_HOST_PORT = re.compile(r"^(\[[0-9a-fA-F:.]+\]|[\w.-]+):\d*$")
_LOOSE_HOST = re.compile(r"^(localhost|[\w-]+(\.[\w-]+)+|\[[0-9a-fA-F:.]+\])$")


def _reads_as_address(text: str, *, loose: bool) -> bool:
    """Whether a first positional argument is the robot's address: a URL
    (``ws://...``, ``tcp/host:port``), ``host:port``; and, before a ROS
    graph name (``loose``), also ``localhost``, a dotted name or an IP
    address (ROS names contain neither ``.`` nor ``:``)."""
    if text.startswith("/"):
        return False
    if "://" in text or text.startswith(("tcp/", "udp/")) or _HOST_PORT.match(text):
        return True
    return loose and bool(_LOOSE_HOST.match(text))


def _find_verb(verbs: list[Verb], command: str, rest: list[str]) -> tuple[Verb, list[str]]:
    """The verb ``command rest...`` names (the longest match) and the
    arguments after its words."""
    words = [command, *rest]
    best: Verb | None = None
    for v in verbs:
        n = len(v.path)
        if tuple(words[:n]) == v.path and (best is None or n > len(best.path)):
            best = v
    if best is None:
        subs = sorted(" ".join(v.path) for v in verbs if v.path[0] == command and not v.hidden)
        if subs:
            raise UsageError(f"'{command}' wants one of: {', '.join(subs)}")
        import difflib

        names = sorted({v.path[0] for v in verbs})
        near = difflib.get_close_matches(command, names, n=3)
        hint = f" (did you mean {' or '.join(near)}?)" if near else ""
        raise UsageError(f"unknown command {command!r}{hint}; see rmb --help")
    return best, words[len(best.path) :]


def _resolve(verb: Verb, ns: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Take the robot's address and the verb's positional arguments out of
    ``ns.args``: ``-u URL`` wins; else the first argument when the verb got
    one more than it takes, or when it reads as an address; else
    ``$RMB_URL``."""
    pos: list[str] = list(ns.args)
    low, high = verb.bounds
    if len(pos) < low:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) : low]
        parser.error(f"missing {' '.join(missing)}")
    if verb.run is not None and not ns.url and pos and len(pos) == low and "://" in pos[0]:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) - 1 : low]
        parser.error(f"missing {' '.join(missing)} (after the address {pos[0]})")
    if verb.run is not None and not ns.url:
        if pos and (
            (len(pos) > high and not pos[0].startswith("/"))  # a ROS name is never the address
            or (len(pos) - 1 >= low and _reads_as_address(pos[0], loose=verb.graph_names))
        ):
            ns.url = pos.pop(0)
        else:
            ns.url = os.environ.get(ENV_URL) or None
        if not ns.url and len(pos) > high:
            _unexpected(parser, pos, high)
        if not ns.url:
            parser.error(
                f"no robot address: give it first (rmb {' '.join(verb.path)} HOST:PORT ...), "
                f"with -u URL, or in ${ENV_URL}"
            )
    if len(pos) < low:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) : low]
        parser.error(f"missing {' '.join(missing)}")
    if len(pos) > high:
        _unexpected(parser, pos, high)
    for i, spec in enumerate(verb.args):
        name = spec.rstrip("?*+").lower()
        if spec.endswith(("*", "+")):
            setattr(ns, name, pos[i:])
        else:
            setattr(ns, name, pos[i] if i < len(pos) else None)


def _unexpected(parser: argparse.ArgumentParser, pos: list[str], high: float) -> None:
    hint = " (quote YAML or JSON as one argument)" if any(":" in p for p in pos) else ""
    parser.error(f"unexpected argument(s): {' '.join(pos[int(high) :])}{hint}")


def parse(argv: Sequence[str]) -> tuple[Verb, argparse.Namespace]:
    """The verb and the namespace of one command line (argparse's exit 2 on
    a usage mistake)."""
    verbs = _verbs()
    top = _top_parser(verbs)
    ns = top.parse_args(argv)
    if ns.command is None:
        top.error("a COMMAND is needed (rmb --help lists them)")
    try:
        verb, rest = _find_verb(verbs, ns.command, list(ns.rest))
    except UsageError as exc:
        top.error(str(exc))
    parser = _verb_parser(verb)
    local = parser.parse_intermixed_args(rest)
    for key, value in vars(local).items():
        setattr(ns, key, value)
    _resolve(verb, ns, parser)
    return verb, ns


# -- running ---------------------------------------------------------------------------------


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


def _leaf(exc: BaseException) -> BaseException:
    """The exception inside (nested) exception groups: the first one that is
    not a cancellation."""
    while isinstance(exc, BaseExceptionGroup):
        inner = [
            e for e in exc.exceptions if type(e).__name__ not in ("Cancelled", "CancelledError")
        ]
        exc = (inner or list(exc.exceptions))[0]
    return exc


def _setup_logging(ns: argparse.Namespace) -> None:
    """``-v``/``--log-level`` set the library's logger (``ros_mobile_bridge``);
    other libraries (websockets' per-frame debug log among them) stay at
    WARNING."""
    level = ns.log_level or {0: "WARNING", 1: "INFO"}.get(ns.verbose, "DEBUG")
    logging.basicConfig(
        level=logging.WARNING,
        format="rmb: %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    logging.getLogger("ros_mobile_bridge").setLevel(getattr(logging, level))


def _say(text: str) -> None:
    print(f"rmb: {text}", file=sys.stderr, flush=True)


def _exit_code_for(exc: BaseException, verbose: bool) -> int:
    if isinstance(exc, BrokenPipeError):
        return _stdout_closed()
    if isinstance(exc, KeyboardInterrupt):
        return 130
    if isinstance(exc, SystemExit):
        code = exc.code
        if isinstance(code, str):
            _say(code.removeprefix("rmb: "))
            return 1
        return int(code or 0)
    if verbose:
        traceback.print_exception(exc)
    if isinstance(exc, UsageError):
        _say(str(exc))
        return 2
    # one line per error, the same way for every class (docs/errors.md):
    # the caller's mistakes (MessageError is a ValueError) exit 2, the
    # robot's refusals and runtime failures 1
    known = isinstance(exc, ValueError | TypeError | RosBridgeError | OSError)
    hint = "" if known or verbose else " (unexpected: run with -v for the traceback)"
    _say(f"{type(exc).__name__}: {exc}{hint}")
    return 2 if isinstance(exc, ValueError | TypeError) else 1


def main(argv: Sequence[str] | None = None) -> int:
    """Run the ``rmb`` command line; returns the exit status (see the
    module docstring)."""
    try:
        verb, ns = parse(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        return 130
    _setup_logging(ns)
    verbose = bool(ns.verbose) or ns.log_level == "DEBUG"
    if ns.backend == "trio":
        try:
            importlib.import_module("trio")
        except ImportError:
            _say("--backend trio needs trio: pip install 'ros-mobile-bridge[trio]'")
            return 2
    try:
        if verb.run_sync is not None:
            return int(verb.run_sync(ns))
        assert verb.run is not None
        return run_signalled(verb.run, ns, backend=ns.backend)
    except BaseException as exc:  # every way out becomes one line and a status
        return _exit_code_for(_leaf(exc), verbose)
