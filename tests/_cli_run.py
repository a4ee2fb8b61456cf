"""The ``rmb`` command line run for the tests, from the checkout, with no
``$RMB_URL`` from the caller's environment. One runner for every CLI test
module.

:func:`rmb` runs ``main(ARGS)`` in this process, as a fresh process would
see it: its own environment, working directory, standard streams, logging
set up anew, and its exit status. Arguments, formats and exit statuses are
checked that way without starting an interpreter per call (hundreds of
calls a run). ``rmb(..., process=True)`` and :func:`rmb_proc` run ``python
-m ros_mobile_bridge ARGS`` in a subprocess with this checkout's sources
first on the path: for what only a process shows (signals, a closed pipe,
the module entry point, import-time behaviour)."""

from __future__ import annotations

import contextlib
import io
import logging
import os
import subprocess
import sys
import threading
from collections.abc import Iterable, Iterator
from pathlib import Path

__all__ = ["PYTHON_SIGINT_DEFAULT", "ROOT", "cli_env", "rmb", "rmb_proc"]

ROOT = Path(__file__).resolve().parent.parent

PYTHON_SIGINT_DEFAULT = [
    sys.executable,
    "-c",
    "import os, signal, sys\n"
    "signal.signal(signal.SIGINT, signal.SIG_DFL)\n"
    "os.execv(sys.executable, [sys.executable, *sys.argv[1:]])",
]
"""``python`` (append its arguments) started with SIGINT's default action,
whatever this process's is. A shell's background job (``cmd &`` without job
control) ignores SIGINT, and a Python started with SIGINT ignored keeps it
ignored: a test that interrupts the program before the program installs a
handler of its own needs this."""


def cli_env(url: str | None = None, *, drop: Iterable[str] = (), **extra: str) -> dict[str, str]:
    """This process's environment without ``$RMB_URL`` (and the ``drop``
    names), with ``url`` as ``$RMB_URL`` when given and ``extra`` set."""
    gone = {"RMB_URL", *drop}
    env = {k: v for k, v in os.environ.items() if k not in gone}
    if url is not None:
        env["RMB_URL"] = url
    env.update(extra)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), *filter(None, [env.get("PYTHONPATH")])])
    return env


def rmb(
    *args: str,
    url: str | None = None,
    env: dict[str, str] | None = None,
    timeout: float = 60,
    process: bool = False,
) -> subprocess.CompletedProcess[str]:
    """``rmb ARGS`` to its end; ``url`` goes in ``$RMB_URL``; ``env`` (from
    :func:`cli_env`) replaces the whole environment. In this process unless
    ``process`` (then ``timeout`` bounds the subprocess)."""
    if not process:
        return _in_process(list(args), env if env is not None else cli_env(url))
    return subprocess.run(
        [sys.executable, "-m", "ros_mobile_bridge", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=ROOT,
        env=env if env is not None else cli_env(url),
        check=False,
    )


def rmb_proc(
    *args: str, url: str | None = None, env: dict[str, str] | None = None
) -> subprocess.Popen[str]:
    """``rmb ARGS`` started, stdout and stderr piped (text)."""
    return subprocess.Popen(
        [sys.executable, "-m", "ros_mobile_bridge", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        env=env if env is not None else cli_env(url),
    )


_LOGGERS = ("ros_mobile_bridge", "ros_mobile_bridge.cli.signals")
"""The loggers whose levels ``main`` sets (``_cli._app._setup_logging``)."""


@contextlib.contextmanager
def _fresh_logging() -> Iterator[None]:
    """The root logger without handlers for the call, as in a new process
    (so ``main``'s ``logging.basicConfig`` installs its own, on the call's
    stderr); everything put back after."""
    root = logging.getLogger()
    saved_handlers, saved_level = root.handlers[:], root.level
    saved_levels = {name: logging.getLogger(name).level for name in _LOGGERS}
    root.handlers.clear()
    try:
        yield
    finally:
        for handler in root.handlers:
            handler.close()
        root.handlers[:] = saved_handlers
        root.setLevel(saved_level)
        for name, level in saved_levels.items():
            logging.getLogger(name).setLevel(level)


def _in_process(args: list[str], env: dict[str, str]) -> subprocess.CompletedProcess[str]:
    """``main(args)`` in this process with ``env`` as the whole environment,
    ``ROOT`` as the working directory and fresh standard streams (text over
    bytes, as a pipe: ``sys.stdout.buffer`` works, nothing is a terminal)."""
    # signal handlers need the main thread, and one call at a time owns the
    # process's environment and streams
    assert threading.current_thread() is threading.main_thread(), "rmb() from the main thread"
    from ros_mobile_bridge.cli import main

    out = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", newline="")
    err = io.TextIOWrapper(io.BytesIO(), encoding="utf-8", newline="")
    saved_env, saved_cwd = dict(os.environ), os.getcwd()
    os.environ.clear()
    os.environ.update(env)
    os.chdir(ROOT)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), _fresh_logging():
            try:
                code = main(args)
            except SystemExit as exc:  # (main returns its status; kept as a process would)
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(saved_cwd)
        os.environ.clear()
        os.environ.update(saved_env)
    return subprocess.CompletedProcess(["rmb", *args], code, _text(out), _text(err))


def _text(stream: io.TextIOWrapper) -> str:
    stream.flush()
    raw = stream.buffer
    assert isinstance(raw, io.BytesIO)
    return raw.getvalue().decode("utf-8", "replace")
