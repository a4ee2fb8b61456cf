"""Process signals as cancellation: what ``timeout``, systemd, ``docker stop``
and CI cancellation send (SIGTERM), a closed terminal (SIGHUP) and Ctrl-C
(SIGINT) end a scope the structured way, so every ``connect()`` block inside
it runs its teardown (zero Twist, then close) instead of the process dying
mid-command."""

from __future__ import annotations

import logging
import signal
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from signal import Signals  # in SignalScope's body, its ``signal`` property hides the module

import anyio
import anyio.abc

__all__ = ["DEFAULT_SIGNALS", "SignalScope", "cancel_on_signals"]

DEFAULT_SIGNALS: tuple[signal.Signals, ...] = tuple(
    getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)
)
"""SIGINT, SIGTERM and SIGHUP (those this platform has)."""


class SignalScope:
    """What :func:`cancel_on_signals` yields. ``signal`` is the signal that
    cancelled the scope, or ``None`` while none has arrived (and after a scope
    that ended another way); ``exit_code`` is ``128 + signal`` (the shell's
    convention: 143 for SIGTERM, 130 for SIGINT), or ``None``."""

    def __init__(self) -> None:
        self._signal: signal.Signals | None = None

    @property
    def signal(self) -> signal.Signals | None:
        """The signal that cancelled the scope, or ``None``."""
        return self._signal

    @property
    def exit_code(self) -> int | None:
        """``128 + signal`` once a signal cancelled the scope, else ``None``."""
        return None if self._signal is None else 128 + int(self._signal)

    async def _watch(
        self,
        signals: tuple[Signals, ...],
        body: anyio.CancelScope,
        log: logging.Logger,
        *,
        task_status: anyio.abc.TaskStatus[None] = anyio.TASK_STATUS_IGNORED,
    ) -> None:
        """Wait for ``signals``: the first one is recorded here and cancels
        ``body``; a second one ends the process."""
        with anyio.open_signal_receiver(*signals) as received:
            task_status.started()
            async for signum in received:
                sig = signal.Signals(signum)
                if self._signal is None:
                    self._signal = sig
                    log.warning("%s received: stopping (send it again to exit at once)", sig.name)
                    body.cancel()
                    continue
                # The teardown is taking too long for whoever sends this: give the
                # signal its default action (for these three: end the process).
                log.error("%s received again: exiting at once, without the teardown", sig.name)
                signal.signal(signum, signal.SIG_DFL)
                signal.raise_signal(signum)


@asynccontextmanager
async def cancel_on_signals(
    *signals: int, logger: logging.Logger | None = None
) -> AsyncIterator[SignalScope]:
    """Cancel the body when the process receives one of ``signals``
    (default: SIGINT, SIGTERM, SIGHUP); an async context manager yielding a
    :class:`SignalScope`.

    The first signal cancels the body like any cancel scope: a ``connect()``
    block inside runs its teardown (a zero Twist to the velocity topics, then
    close), and the block ends without an exception; ``scope.signal`` then
    names the signal, so a program can ``sys.exit(scope.exit_code)`` (128 +
    signal number, what a shell reports for a process killed by it). A
    second signal while the body still winds down (say a teardown waiting on
    a dead network) restores that signal's default action and re-raises it:
    the process ends at once. Other exceptions from the body pass through
    unchanged (not wrapped in an exception group).

    While the block runs, the signals' previous handlers are replaced (and
    restored when it ends); KeyboardInterrupt is not raised for SIGINT inside
    it. Works on asyncio and trio, on POSIX, from the main thread only (where
    Python delivers signals). Built on :func:`anyio.open_signal_receiver` in a
    task group of its own."""
    for s in signals:
        if isinstance(s, bool) or not isinstance(s, int):
            raise TypeError(f"signals must be signal numbers, got {s!r}")
    chosen = tuple(signal.Signals(s) for s in signals) if signals else DEFAULT_SIGNALS
    log = logger if logger is not None else logging.getLogger("ros_mobile_bridge")
    scope = SignalScope()
    body = anyio.CancelScope()
    body_error: BaseException | None = None
    cancelled = anyio.get_cancelled_exc_class()
    async with anyio.create_task_group() as tg:
        # the scope records the signal and cancels the body itself (a method of this module's class)
        await tg.start(scope._watch, chosen, body, log)
        try:
            with body:
                yield scope
        except cancelled:
            raise  # an outer scope's cancellation: the task group passes it on
        except BaseException as exc:  # re-raised below, outside the task group
            body_error = exc
        finally:
            tg.cancel_scope.cancel()
    if body_error is not None:
        try:
            raise body_error
        finally:
            body_error = None
