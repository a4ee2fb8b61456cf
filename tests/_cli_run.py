"""The ``rmb`` command line run as a user runs it: ``python -m
ros_mobile_bridge ARGS`` in a subprocess, from the checkout, with this
checkout's sources first on the path and no ``$RMB_URL`` from the caller's
environment. One runner for every CLI test module."""

from __future__ import annotations

import os
import subprocess
import sys
from collections.abc import Iterable
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
    *args: str, url: str | None = None, env: dict[str, str] | None = None, timeout: float = 60
) -> subprocess.CompletedProcess[str]:
    """``rmb ARGS`` to its end; ``url`` goes in ``$RMB_URL``; ``env`` (from
    :func:`cli_env`) replaces the whole environment."""
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
