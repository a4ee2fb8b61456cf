"""What the verb modules (``_topic``, ``_ros``, ``_record``, ``_demo``) need
from the command line's core: the :class:`Verb` record they list their
commands in, and :func:`run_signalled`. Below ``_app``, which imports the
verb modules; they never import ``_app``. Light: anyio and the signal scope
are imported when a verb runs, not when the command line is parsed."""

from __future__ import annotations

import argparse
import logging
from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any

__all__ = ["SIGNAL_LOGGER", "AsyncRun", "Verb", "run_signalled"]

SIGNAL_LOGGER = "ros_mobile_bridge.cli.signals"
"""The logger the command's signal scope writes to. A Ctrl-C the user asked
for is no warning: ``_app`` keeps this logger at ERROR unless ``-v`` (a
second Ctrl-C, which skips the teardown, is still said)."""

AsyncRun = Callable[[argparse.Namespace], Awaitable[int]]


@dataclass(frozen=True)
class Verb:
    """One command: ``path`` its words (``("param", "get")``), ``args`` its
    positional arguments (``"NAME"``, ``"NAME?"`` optional, ``"NAME*"`` any
    number), ``build`` adds its options, and exactly one of ``run`` (async,
    connected to a robot) or ``run_sync`` (no robot address) runs it.
    ``graph_names``: its first argument is a ROS graph name (topic, service,
    action), so a bare host name before it is read as the address.
    ``usage``: the arguments' usage text when ``args`` cannot say it (a
    leading optional NODE)."""

    path: tuple[str, ...]
    help: str
    args: tuple[str, ...] = ()
    build: Callable[[argparse.ArgumentParser], None] | None = None
    run: AsyncRun | None = None
    run_sync: Callable[[argparse.Namespace], int] | None = None
    graph_names: bool = True
    hidden: bool = False
    usage: str = ""

    @property
    def bounds(self) -> tuple[int, float]:
        low = sum(1 for a in self.args if not a.endswith(("?", "*")))
        high = float("inf") if any(a.endswith(("*", "+")) for a in self.args) else len(self.args)
        return low, high

    @property
    def usage_args(self) -> str:
        if self.usage:
            return self.usage
        parts = []
        for a in self.args:
            name = a.rstrip("?*+")
            if a.endswith("?"):
                parts.append(f"[{name}]")
            elif a.endswith("*"):
                parts.append(f"[{name} ...]")
            elif a.endswith("+"):
                parts.append(f"{name} [{name} ...]")
            else:
                parts.append(name)
        return " ".join(parts)


def run_signalled(fn: Callable[..., Awaitable[Any]], *args: Any, backend: str) -> int:
    """Run ``fn(*args)`` on ``backend`` (a name of :data:`.._loop._backends.BACKENDS`), cancelled by SIGINT, SIGTERM or
    SIGHUP (so every ``connect()`` block runs its teardown); the exit status
    is 128 + signal then, else what ``fn`` returned (None: 0). A second
    signal ends the process at once."""
    import anyio

    from .._loop._backends import run_args
    from .._signals import cancel_on_signals

    async def signalled() -> int:
        code: Any = 0
        async with cancel_on_signals(logger=logging.getLogger(SIGNAL_LOGGER)) as stop:
            code = await fn(*args)
        if stop.exit_code is not None:
            return stop.exit_code
        return int(code or 0)

    loop, loop_options = run_args(backend, None, f"--backend {backend}")
    return int(anyio.run(signalled, backend=loop, backend_options=loop_options))
