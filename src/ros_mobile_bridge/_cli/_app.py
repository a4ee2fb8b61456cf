"""The ``rmb`` entry point: global options, the verb table, where the robot's
address comes from, and how every failure becomes one line and an exit code.

Exit codes: 0 done; 1 a runtime failure (refused connection, a service that
failed, nothing found or set); 2 a usage mistake (bad option, bad YAML, a
field the type does not have); 128 + signal when stopped by SIGINT (130),
SIGTERM (143) or SIGHUP (129), every teardown having run; 141 when stdout's
reader went away (``rmb echo ... | head -1``).

Light on purpose: ``rmb --version``, ``rmb --help`` and a group's help
(``rmb topic --help``) are answered from the index in ``_table`` and import
no verb module, no anyio, no client and no codec; a verb's module is
imported when the verb is parsed for running (or its own ``--help``)."""

from __future__ import annotations

import argparse
import contextlib
import importlib
import os
import re
import signal
import sys
import traceback
from collections.abc import Sequence
from typing import Any, NoReturn

from .._errors import RosBridgeError
from .._loop._backends import BACKENDS, run_args
from .._version import __version__
from ._format import UsageError
from ._table import ENTRIES, GROUP_HELP, Entry, group_entries, groups
from ._verb import SIGNAL_LOGGER, Verb, run_signalled

if sys.version_info < (3, 11):  # pragma: no cover - the backport anyio installs there
    from exceptiongroup import BaseExceptionGroup

__all__ = ["ENV_URL", "Verb", "load_verb", "main", "parse"]

ENV_URL = "RMB_URL"
"""The environment variable holding the robot's address when none is given."""

_EXIT_CODES = (
    "Exit codes: 0 ok, 1 runtime failure, 2 usage mistake, 130 Ctrl-C (SIGINT), "
    "143 SIGTERM, 129 SIGHUP, 141 stdout closed."
)


def load_verb(entry: Entry) -> Verb:
    """The :class:`Verb` ``entry`` indexes, its module imported now."""
    module = importlib.import_module(f"{__package__}.{entry.module}")
    for verb in module.VERBS:
        if verb.path == entry.path:
            return verb  # type: ignore[no-any-return]
    raise LookupError(f"{entry.module} lists no verb {' '.join(entry.path)!r}")


# -- parsing -------------------------------------------------------------------------------


class _VerboseGoesFirst(argparse.Action):
    """``-v`` after a verb that has no ``-v`` of its own: since ``topics -v``
    became ros2's verbose listing, log verbosity is asked for before the
    verb (``rmb -v echo /odom``), or with ``--log-level`` anywhere."""

    def __call__(self, parser: argparse.ArgumentParser, *_args: Any, **_kw: Any) -> NoReturn:
        parser.error("-v (log more) goes before the command: rmb -v COMMAND ... (or --log-level)")


def _common_options(p: argparse.ArgumentParser, *, default: Any, top: bool) -> None:
    """The options every verb takes, before or after the verb's name (``-v``
    before it only). In a verb's parser they default to
    ``argparse.SUPPRESS`` so that the global value stays unless repeated
    there."""
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
        choices=BACKENDS,
        default=d("asyncio"),
        help="event loop (default asyncio; uvloop: asyncio on uvloop)",
    )
    if top:
        p.add_argument(
            "-v",
            "--verbose",
            action="count",
            default=0,
            help="before the command: log more (-v info, -vv debug) and show tracebacks",
        )
    p.add_argument(
        "--log-level",
        default=d(None),
        type=str.upper,
        choices=("DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"),
        help="log level of the library's logger (default WARNING)",
    )


def _top_parser() -> argparse.ArgumentParser:
    lines = [f"  {' '.join(e.path):<18} {e.help}" for e in ENTRIES if not e.hidden]
    group_lines = [f"  {g:<18} {GROUP_HELP.get(g, '')}".rstrip() for g in groups()]
    parser = argparse.ArgumentParser(
        prog="rmb",
        usage="rmb [options] COMMAND [URL] [ARGS ...]",
        description="ROS 2 robots from Python, without ROS: the ros2 command's verbs over "
        "Foxglove WebSocket, rosbridge and Zenoh.",
        epilog="commands:\n"
        + "\n".join(lines)
        + "\n\ngroups ('rmb GROUP --help' lists a group's verbs, ros2 spellings included):\n"
        + "\n".join(group_lines)
        + f"\n\nThe robot's address: -u URL, else an argument that reads as one (first, or "
        f"last after a ROS name), else ${ENV_URL}.\n'rmb COMMAND --help' for a command's "
        f"options. {_EXIT_CODES}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "--version", action="version", version=f"rmb (ros-mobile-bridge) {__version__}"
    )
    _common_options(parser, default=None, top=True)
    parser.add_argument(
        "command",
        metavar="COMMAND",
        nargs="?",
        help=", ".join(sorted({e.path[0] for e in ENTRIES})),
    )
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
        _common_options(parser, default=argparse.SUPPRESS, top=False)
    else:
        parser.add_argument("--backend", choices=BACKENDS, default=argparse.SUPPRESS)
    if verb.build is not None:
        verb.build(parser)
    with contextlib.suppress(argparse.ArgumentError):  # a verb's own -v (topics -v) wins
        parser.add_argument(
            "-v",
            "--verbose",
            nargs=0,
            action=_VerboseGoesFirst,
            default=argparse.SUPPRESS,
            help=argparse.SUPPRESS,
        )
    parser.add_argument("args", nargs="*", help=argparse.SUPPRESS)
    return parser


def _group_listing(group: str) -> str:
    entries = group_entries(group)
    width = max(len(" ".join(e.path)) for e in entries) + 2
    lines = [f"usage: rmb {group} VERB [options] [URL] [ARGS ...]", ""]
    if group in GROUP_HELP:
        lines += [GROUP_HELP[group], ""]
    lines.append("verbs:")
    lines += [f"  {' '.join(e.path):<{width}} {e.help}" for e in entries]
    lines += ["", f"'rmb {group} VERB --help' for a verb's options. {_EXIT_CODES}"]
    return "\n".join(lines) + "\n"


def _find_entry(command: str, rest: list[str]) -> tuple[Entry, list[str]]:
    """The verb ``command rest...`` names (the longest match) and the
    arguments after its words. A group's name alone, or with ``-h`` /
    ``--help``, prints the group's verbs (exit 2 / 0)."""
    words = [command, *rest]
    best: Entry | None = None
    for e in ENTRIES:
        n = len(e.path)
        if tuple(words[:n]) == e.path and (best is None or n > len(best.path)):
            best = e
    if best is None and command in groups():
        listing = _group_listing(command)
        if rest and rest[0] in ("-h", "--help"):
            sys.stdout.write(listing)
            raise SystemExit(0)
        if not rest:
            sys.stderr.write(listing)
            raise SystemExit(2)
        verbs = ", ".join(e.path[1] for e in group_entries(command))
        raise UsageError(f"'{command}' has no verb {rest[0]!r}; it has: {verbs}")
    if best is None:
        import difflib

        names = sorted({e.path[0] for e in ENTRIES})
        near = difflib.get_close_matches(command, names, n=3)
        hint = f" (did you mean {' or '.join(near)}?)" if near else ""
        raise UsageError(f"unknown command {command!r}{hint}; see rmb --help")
    return best, words[len(best.path) :]


_HOST_PORT = re.compile(r"^(\[[0-9a-fA-F:.]+\]|[\w.-]+):\d*$")
_STRICT_HOST_PORT = re.compile(r"^(\[[0-9a-fA-F:.]+\]|[\w.-]+):\d+$")
_LOOSE_HOST = re.compile(r"^(localhost|[\w-]+(\.[\w-]+)+|\[[0-9a-fA-F:.]+\])$")


def _reads_as_address(text: str, *, loose: bool) -> bool:
    """Whether a first positional argument is the robot's address: a URL
    (``ws://...``, ``tcp/host:port``, ``tls/host:port``), ``host:port``; and, before a ROS
    graph name (``loose``), also ``localhost``, a dotted name or an IP
    address (ROS names contain neither ``.`` nor ``:``)."""
    if text.startswith("/"):
        return False
    if "://" in text or text.startswith(("tcp/", "tls/", "udp/")) or _HOST_PORT.match(text):
        return True
    return loose and bool(_LOOSE_HOST.match(text))


def _trailing_address(text: str) -> bool:
    """Whether an argument after a ROS name is the robot's address (``rmb
    echo /odom 127.0.0.1:8765``): a URL or ``host:port`` with a port. Types,
    names and YAML mappings never read so."""
    return (
        "://" in text
        or text.startswith(("tcp/", "tls/", "udp/"))
        or bool(_STRICT_HOST_PORT.match(text))
    )


def _address_at(verb: Verb, pos: list[str]) -> int | None:
    """Which positional argument is the robot's address, if one is: the
    first when the verb got one more than it takes (a ROS name is never the
    address) or when it reads as one; the first before an absolute name
    (``rmb echo myrobot /odom``); the last after a ROS name when it reads
    as ``host:port`` or a URL (``rmb echo /odom 127.0.0.1:8765``)."""
    low, high = verb.bounds
    if not pos:
        return None
    spare = len(pos) - 1 >= low
    if len(pos) > high and not pos[0].startswith("/"):
        return 0
    if spare and _reads_as_address(pos[0], loose=verb.graph_names):
        return 0
    if not (verb.graph_names and spare and len(pos) >= 2):
        return None
    if high != float("inf") and pos[1].startswith("/") and not pos[0].startswith("/"):
        return 0
    if _trailing_address(pos[-1]):
        return len(pos) - 1
    return None


def _resolve(verb: Verb, ns: argparse.Namespace, parser: argparse.ArgumentParser) -> None:
    """Take the robot's address and the verb's positional arguments out of
    ``ns.args``: ``-u URL`` wins; else an argument that reads as the
    address (:func:`_address_at`); else ``$RMB_URL``. Graph names come out
    absolute; a mistake in the arguments is said before a missing
    address."""
    pos: list[str] = list(ns.args)
    low, high = verb.bounds
    if len(pos) < low:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) : low]
        parser.error(f"missing {' '.join(missing)}")
    if verb.run is not None and not ns.url and pos and len(pos) == low and "://" in pos[0]:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) - 1 : low]
        parser.error(f"missing {' '.join(missing)} (after the address {pos[0]})")
    if verb.run is not None and not ns.url:
        at = _address_at(verb, pos)
        ns.url = pos.pop(at) if at is not None else os.environ.get(ENV_URL) or None
    if len(pos) < low:
        missing = [a.rstrip("?*+") for a in verb.args][len(pos) : low]
        parser.error(f"missing {' '.join(missing)}")
    if len(pos) > high:
        _unexpected(parser, pos, high)
    last = len(verb.args) - 1
    for i, spec in enumerate(verb.args):
        name = spec.rstrip("?*+").lower()
        if spec.endswith(("*", "+")):
            setattr(ns, name, [_graph(parser, name, p) for p in pos[i:]])
            continue
        value = _graph(parser, name, pos[i]) if i < len(pos) else None
        if spec == "TYPE?" and i == last and value is not None and not _TYPE.match(value):
            _unexpected(parser, pos, i)  # echo /odom extra: not a type
        setattr(ns, name, value)
    if verb.run is not None and not ns.url:
        parser.error(
            f"no robot address: give it first (rmb {' '.join(verb.path)} HOST:PORT ...), "
            f"with -u URL, or in ${ENV_URL}"
        )


_TYPE = re.compile(r"^[A-Za-z]\w*/(\w+/)?[A-Za-z]\w*$")
"""A ROS type name, ``pkg/msg/Type`` or ``pkg/Type``."""


_GRAPH_ARGS = frozenset({"topic", "service", "action", "node"})
"""The positional arguments (by their name in :attr:`Verb.args`) that are
graph names, resolved against ``/`` as ros2 does (``odom`` is ``/odom``)."""


def _graph(parser: argparse.ArgumentParser, name: str, value: str) -> str:
    if name not in _GRAPH_ARGS:
        return value
    from ._common import graph_name

    try:
        return graph_name(value, name)
    except UsageError as exc:
        parser.error(str(exc))


def _split_yaml(pos: list[str]) -> bool:
    """Whether the arguments look like one YAML mapping the shell split at
    its spaces (``linear:`` ``{x: 1}``): a word ending in ``:`` or ``,``, or
    braces or brackets left open or closed alone."""
    for word in pos:
        if word.endswith((":", ",")) or word in ("{", "}", "[", "]"):
            return True
        if word.count("{") != word.count("}") or word.count("[") != word.count("]"):
            return True
    return False


def _unexpected(parser: argparse.ArgumentParser, pos: list[str], high: float) -> None:
    hint = " (quote YAML or JSON as one argument)" if _split_yaml(pos) else ""
    parser.error(f"unexpected argument(s): {' '.join(pos[int(high) :])}{hint}")


def parse(argv: Sequence[str]) -> tuple[Verb, argparse.Namespace]:
    """The verb and the namespace of one command line (argparse's exit 2 on
    a usage mistake; exit 0 after printing help)."""
    top = _top_parser()
    ns = top.parse_args(argv)
    if ns.command is None:
        top.error("a COMMAND is needed (rmb --help lists them)")
    try:
        entry, rest = _find_entry(ns.command, list(ns.rest))
    except UsageError as exc:
        top.error(str(exc))
    verb = load_verb(entry)
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
    WARNING. The Ctrl-C the user typed is not a warning: the signal scope's
    logger stays at ERROR unless ``-v``."""
    import logging

    level = ns.log_level or {0: "WARNING", 1: "INFO"}.get(ns.verbose, "DEBUG")
    logging.basicConfig(
        level=logging.WARNING,
        format="rmb: %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    logging.getLogger("ros_mobile_bridge").setLevel(getattr(logging, level))
    if not ns.verbose:
        logging.getLogger(SIGNAL_LOGGER).setLevel(logging.ERROR)


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
    module docstring). A Ctrl-C at any moment in here (while parsing, while
    a verb's module is imported, before a connection's signal scope is in
    place) is exit 130 with no traceback."""
    try:
        return _main(sys.argv[1:] if argv is None else argv)
    except KeyboardInterrupt:
        return 130


def _main(argv: Sequence[str]) -> int:
    try:
        verb, ns = parse(argv)
    except SystemExit as exc:  # argparse: help printed (0) or a usage mistake (2)
        return exc.code if isinstance(exc.code, int) else 2
    _setup_logging(ns)
    verbose = bool(ns.verbose) or ns.log_level == "DEBUG"
    try:  # the loop's package, before anything starts
        run_args(ns.backend, None, f"--backend {ns.backend}")
    except ImportError as exc:
        _say(str(exc))
        return 2
    try:
        if verb.run_sync is not None:
            return int(verb.run_sync(ns))
        assert verb.run is not None
        return run_signalled(verb.run, ns, backend=ns.backend)
    except KeyboardInterrupt:
        return 130
    except BaseException as exc:  # every way out becomes one line and a status
        return _exit_code_for(_leaf(exc), verbose)
