"""What the server sent and the client skipped: counted, and logged at a
bounded rate.

Every skipped or refused input is counted per reason for the client's life
(``Client.rejections``). The log gets a line for each of the first
:data:`LOG_BURST` inputs of a reason in a window of :data:`LOG_EVERY`
seconds; the rest of that window are counted into one line, logged when
the reason next comes up after the window (or when the client closes). A
server, or a publisher on a Zenoh key, that sends a thousand bad inputs a
second costs at most 11 lines a second per reason, not a thousand, and a
few distinct mistakes are each still shown. Once flushed, the lines add up
to the counts.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import Final

from ..wire._limits import truncate_for_log

__all__ = ["LOG_BURST", "LOG_EVERY", "RejectionLog"]

LOG_EVERY: Final = 1.0
"""Seconds of one window of the rejections' log, per reason."""
LOG_BURST: Final = 10
"""Inputs of one reason logged one by one per window; the rest are one line."""


class _Window:
    """One reason's current window of the log."""

    __slots__ = ("lines", "start", "unlogged")

    def __init__(self, start: float) -> None:
        self.start = start
        self.lines = 0  # logged one by one in this window
        self.unlogged = 0  # inputs counted in this window past LOG_BURST


class RejectionLog:
    """The counts of one client's rejections and their rate-limited log.
    ``clock`` (monotonic seconds) is injectable for tests."""

    __slots__ = ("_clock", "_counts", "_log", "_windows")

    def __init__(self, logger: logging.Logger, clock: Callable[[], float] = time.monotonic) -> None:
        self._log = logger
        self._clock = clock
        self._counts: dict[str, int] = {}
        self._windows: dict[str, _Window] = {}

    @property
    def counts(self) -> dict[str, int]:
        """Inputs skipped or refused per reason so far (a copy)."""
        return dict(self._counts)

    def add(self, reason: str, detail: str, count: int = 1) -> None:
        """``count`` inputs were skipped for ``reason``; ``detail`` says what
        (untruncated: the line truncates it)."""
        self._counts[reason] = self._counts.get(reason, 0) + count
        now = self._clock()
        window = self._windows.get(reason)
        if window is None or now - window.start >= LOG_EVERY:
            if window is not None and window.unlogged:
                self._summary(reason, window.unlogged, now - window.start)
            window = self._windows[reason] = _Window(now)
        if window.lines >= LOG_BURST:
            window.unlogged += count
            return
        window.lines += 1
        shown = truncate_for_log(detail)
        if count == 1:
            self._log.warning("skipped input from the server (%s): %s", reason, shown)
        else:
            self._log.warning("skipped %d inputs from the server (%s): %s", count, reason, shown)

    def _summary(self, reason: str, waiting: int, seconds: float) -> None:
        self._log.warning(
            "skipped %d inputs from the server (%s) in the last %.1f s, past the %d "
            "logged one by one",
            waiting,
            reason,
            seconds,
            LOG_BURST,
        )

    def flush(self) -> None:
        """Log what was counted but not logged yet (the client is closing)."""
        now = self._clock()
        for reason, window in self._windows.items():
            if window.unlogged:
                self._summary(reason, window.unlogged, now - window.start)
        self._windows.clear()
