"""The event-loop lag monitor: the signal the adaptive throttle and the
circuit breaker read.

A sampler task sleeps ``interval`` seconds again and again; how much later
than asked it wakes up is the loop's lag (time the loop spent on other work,
or blocked). One monitor serves one event loop, whatever the number of
clients on it.

Three signals are kept up to date on every sample, so reading them costs
O(1) (the throttle reads them for every received frame):

- :meth:`LagMonitor.recurring_lag_ms`: the highest lag that at least three
  samples of the last second reached (the third-largest sample; when the
  last second holds fewer than three samples, the newest three count). A
  loop that stays busy raises it within a few samples; one stall (user code
  blocking the loop once, a one-off build) never does. The TIGHTEN signal.
- :meth:`LagMonitor.sustained_lag_ms`: the 90th percentile of the last four
  seconds, and never more than three samples reached. One spike does not
  move it, and it falls only once the loop has been calm for a while: the
  RELAX signal (and a slower TIGHTEN signal for a loop so busy that it
  samples less than three times a second).
- :meth:`LagMonitor.max_lag_ms`: the largest sample of the last second. It
  rises at once with a spike; a diagnostic, not used to throttle.

With fewer than three samples (a monitor that just started) the recurring
and sustained signals read 0.0: nothing is sustained yet.

The signals describe the loop while it was watched without a break. When
the last participant leaves, nothing samples; when sampling starts again,
the signals start over (the history stays for :meth:`LagMonitor.stats`). A
window reaching back over the unwatched time would hold the old samples and
none of the time in between: the single stalls of a few short-lived
clients (a connect, a decoder build) would add up to a "sustained" lag that
throttles the next client's subscriptions for a calm loop.

Percentiles use the nearest-rank method: the p-th percentile of ``n`` samples
is the ``ceil(p * n / 100)``-th smallest. A sample belongs to a window of
``w`` seconds while it is younger than ``w`` (``now - t < w``), where ``now``
is the time of the newest sample: the signals move only when a sample is
recorded.

Ownership: the sampler runs inside a client's task group. Every client on a
loop runs :func:`participate` as one of its own tasks; the first participant
samples, the others wait, and when the sampling participant is cancelled
(its client closed) a waiting one takes over at once. When the last leaves,
sampling stops; the history stays readable until :meth:`LagMonitor.clear`.

The same sampler drives the clients' periodic work: callbacks registered
with :meth:`LagMonitor.add_tick` run every ``tick_interval`` (200 ms), right
after a sample, in the sampling task. One wake-up per loop serves every
client on it, so a thousand idle clients cost what one does.
"""

from __future__ import annotations

import bisect
import heapq
import logging
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from typing import Final, NoReturn

import anyio
from anyio.lowlevel import RunVar

from .._loop._relay import Relay

_log = logging.getLogger("ros_mobile_bridge.lag")

__all__ = [
    "LagMonitor",
    "LagStats",
    "clear",
    "current_monitor",
    "history_csv",
    "max_lag_ms",
    "participate",
    "recurring_lag_ms",
    "stats",
    "sustained_lag_ms",
]

Clock = Callable[[], float]

_SUSTAINED_PERCENTILE: Final = 90
RECURRING_SAMPLES: Final = 3
"""How many samples must reach a lag before the recurring and sustained
signals report it: one or two stalls are not saturation."""


def _check_positive(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{name} must be a number, not {type(value).__name__}")
    if not (value > 0 and math.isfinite(value)):
        raise ValueError(f"{name} must be a positive finite number, got {value!r}")
    return float(value)


def _nearest_rank(ordered: list[float], percent: int) -> float:
    """The ``percent``-th percentile (nearest rank) of an ascending list."""
    n = len(ordered)
    if n == 0:
        return 0.0
    rank = -(-percent * n // 100)  # ceil(percent * n / 100) in integers
    return ordered[min(max(rank, 1), n) - 1]


@dataclass(frozen=True, slots=True)
class LagStats:
    """Event-loop lag over the monitor's kept history (about two minutes),
    in milliseconds: nearest-rank percentiles, the maximum and the number of
    samples. All zero when there are no samples."""

    p50_ms: float
    p90_ms: float
    p99_ms: float
    max_ms: float
    count: int


class LagMonitor:
    """Samples one event loop's lag and keeps its recent history.

    ``clock`` returns monotonic seconds; it timestamps samples and drives the
    sampler, and is injectable so window logic is testable exactly.
    ``interval`` is the sampler's sleep, seconds. Samples older than
    ``history_seconds`` (relative to the newest one) are dropped.
    ``max_window_s`` and ``sustained_window_s`` are the windows of
    :meth:`max_lag_ms` and :meth:`sustained_lag_ms`. ``tick_interval`` is
    how often the sampler runs the callbacks of :meth:`add_tick`.

    Not thread-safe: use it from its event loop's thread only."""

    def __init__(
        self,
        *,
        interval: float = 0.05,
        clock: Clock = time.monotonic,
        history_seconds: float = 120.0,
        max_window_s: float = 1.0,
        sustained_window_s: float = 4.0,
        tick_interval: float = 0.2,
    ) -> None:
        self.interval = _check_positive("interval", interval)
        self.tick_interval = _check_positive("tick_interval", tick_interval)
        self.history_seconds = _check_positive("history_seconds", history_seconds)
        self.max_window_s = _check_positive("max_window_s", max_window_s)
        self.sustained_window_s = _check_positive("sustained_window_s", sustained_window_s)
        self._clock = clock
        self._history: deque[tuple[float, float]] = deque()
        # decreasing lags: the head is the max of the 1 s window
        self._max_window: deque[tuple[float, float]] = deque()
        # the sustained window in time order, and its lags sorted
        self._sustained_window: deque[tuple[float, float]] = deque()
        self._sustained_sorted: list[float] = []
        # the last second's samples, and at least the newest RECURRING_SAMPLES
        self._recent: deque[tuple[float, float]] = deque()
        self._max_lag_ms = 0.0
        self._recurring_lag_ms = 0.0
        self._sustained_lag_ms = 0.0
        self.generation = 0
        """Moves on every :meth:`record` and :meth:`clear` (the only times
        the signals change): a reader may keep what it derived from them
        while it stays the same (the adaptive throttles do, per frame)."""
        self._relay = Relay()
        self._unwatched = False  # nobody sampled since the last participant left
        self._ticks: dict[int, Callable[[], object]] = {}
        self._next_tick_key = 0

    # -- signals (O(1)) --------------------------------------------------------
    def max_lag_ms(self) -> float:
        """The largest lag of the last ``max_window_s`` (1 s) before the
        newest sample, in ms; 0.0 with no samples. A diagnostic: one stall
        shows here at once, and the throttle does not react to it."""
        return self._max_lag_ms

    def recurring_lag_ms(self) -> float:
        """The highest lag at least three samples of the last
        ``max_window_s`` (1 s) reached, in ms (the window reaches back to
        the newest three samples when it holds fewer); 0.0 with fewer than
        three samples. The TIGHTEN signal: a loop that stays busy raises it
        within three samples, a single stall never does."""
        return self._recurring_lag_ms

    def sustained_lag_ms(self) -> float:
        """The 90th percentile (nearest rank) of the lag over the last
        ``sustained_window_s`` (4 s) before the newest sample, capped at
        what at least three samples reached, in ms; 0.0 with fewer than
        three samples in the window. The RELAX signal."""
        return self._sustained_lag_ms

    # -- recording -----------------------------------------------------------
    def record(self, lag_ms: float, now: float | None = None) -> None:
        """Add one sample taken at ``now`` (the clock's time when None) and
        update both signals. Negative or NaN lags count as 0. Times must not
        go back: an earlier ``now`` than the newest sample's is taken as the
        newest sample's time."""
        lag = float(lag_ms) if lag_ms > 0.0 else 0.0
        t = self._clock() if now is None else float(now)
        history = self._history
        if history and t < history[-1][0]:
            t = history[-1][0]
        sample = (t, lag)
        history.append(sample)
        cutoff = t - self.history_seconds
        while history[0][0] <= cutoff:
            history.popleft()

        max_window = self._max_window
        while max_window and max_window[-1][1] <= lag:
            max_window.pop()
        max_window.append(sample)
        cutoff = t - self.max_window_s
        while max_window[0][0] <= cutoff:
            max_window.popleft()
        self._max_lag_ms = max_window[0][1]

        recent = self._recent
        recent.append(sample)
        while len(recent) > RECURRING_SAMPLES and recent[0][0] <= cutoff:
            recent.popleft()
        self._recurring_lag_ms = (
            heapq.nlargest(RECURRING_SAMPLES, [lag for _, lag in recent])[-1]
            if len(recent) >= RECURRING_SAMPLES
            else 0.0
        )

        window = self._sustained_window
        ordered = self._sustained_sorted
        window.append(sample)
        bisect.insort(ordered, lag)
        cutoff = t - self.sustained_window_s
        while window[0][0] <= cutoff:
            _, old = window.popleft()
            del ordered[bisect.bisect_left(ordered, old)]
        n = len(ordered)
        if n < RECURRING_SAMPLES:
            self._sustained_lag_ms = 0.0
        else:
            rank = min(-(-_SUSTAINED_PERCENTILE * n // 100), n - RECURRING_SAMPLES + 1)
            self._sustained_lag_ms = ordered[rank - 1]
        self.generation += 1

    def clear(self) -> None:
        """Forget every sample; both signals read 0.0 until the next one."""
        self._history.clear()
        self._restart_signals()

    def _restart_signals(self) -> None:
        """Empty the signals' windows (not the history): every signal reads
        0.0 until new samples fill them."""
        self._max_window.clear()
        self._sustained_window.clear()
        self._sustained_sorted.clear()
        self._recent.clear()
        self._max_lag_ms = 0.0
        self._recurring_lag_ms = 0.0
        self._sustained_lag_ms = 0.0
        self.generation += 1

    # -- diagnostics -----------------------------------------------------------
    def __len__(self) -> int:
        """The number of samples kept."""
        return len(self._history)

    def stats(self) -> LagStats:
        """Percentiles (nearest rank), maximum and count over the kept
        history. O(n log n): meant for diagnostics, not the hot path."""
        ordered = sorted(lag for _, lag in self._history)
        if not ordered:
            return LagStats(0.0, 0.0, 0.0, 0.0, 0)
        return LagStats(
            p50_ms=_nearest_rank(ordered, 50),
            p90_ms=_nearest_rank(ordered, 90),
            p99_ms=_nearest_rank(ordered, 99),
            max_ms=ordered[-1],
            count=len(ordered),
        )

    def history_csv(self) -> str:
        """The kept history as CSV for bug reports: a ``time_s,lag_ms``
        header, then one ``time_s,lag_ms`` row per sample, oldest first, each
        line ending in a newline. ``time_s`` is seconds since the oldest kept
        sample (so the first row is ``0.000``), three decimals; ``lag_ms``
        has three decimals."""
        history = self._history
        lines = ["time_s,lag_ms\n"]
        if history:
            start = history[0][0]
            lines.extend(f"{t - start:.3f},{lag:.3f}\n" for t, lag in history)
        return "".join(lines)

    # -- sampling ----------------------------------------------------------------
    @property
    def participants(self) -> int:
        """How many :meth:`participate` calls are running."""
        return self._relay.participants

    @property
    def sampling(self) -> bool:
        """Whether a participant is sampling now."""
        return self._relay.running

    # -- the shared tick ----------------------------------------------------------
    def add_tick(self, callback: Callable[[], object]) -> int:
        """Run ``callback()`` every ``tick_interval`` seconds, right after a
        sample, in the sampling task, while any participant samples. Returns
        the key for :meth:`remove_tick`. The callback must not block: it
        runs between two samples, for every client on the loop. An exception
        it raises is logged and the others still run."""
        key = self._next_tick_key
        self._next_tick_key += 1
        self._ticks[key] = callback
        return key

    def remove_tick(self, key: int) -> None:
        """Stop running the callback :meth:`add_tick` returned ``key`` for
        (a key already removed is ignored)."""
        self._ticks.pop(key, None)

    @property
    def ticks(self) -> int:
        """How many tick callbacks are registered."""
        return len(self._ticks)

    def run_ticks(self) -> None:
        """Run every registered tick callback once (the sampler calls this)."""
        for callback in list(self._ticks.values()):
            try:
                callback()
            except Exception:  # one client's bug must not stop the others' ticks
                _log.exception("a periodic callback failed")

    async def run(self) -> NoReturn:
        """The sampler loop, until cancelled: sleep ``interval``, record how
        much later than that the loop woke (ms, at least 0), and every
        ``tick_interval`` run the tick callbacks. Normally driven by
        :meth:`participate`, which guarantees one sampler per monitor. After
        a time when no participant sampled, the signals start over (see the
        module docstring)."""
        if self._unwatched:
            self._unwatched = False
            self._restart_signals()
        clock = self._clock
        interval = self.interval
        next_tick = clock() + self.tick_interval
        while True:
            start = clock()
            await anyio.sleep(interval)
            now = clock()
            self.record((now - start - interval) * 1000.0, now)
            if now >= next_tick:
                next_tick = now + self.tick_interval
                if self._ticks:
                    self.run_ticks()

    async def participate(self) -> NoReturn:
        """Take part in sampling until cancelled: the first participant
        samples (:meth:`run`), later ones wait; when the sampling participant
        is cancelled, a waiting one takes over at once. With no participants
        left nothing samples, and the history is kept; the signals start
        over with the next sampler (a hand-over keeps them)."""
        await self._relay.participate(self.run, self._left)

    def _left(self) -> None:
        self._unwatched = True


# -- one monitor per event loop ----------------------------------------------------
_MONITOR: RunVar[LagMonitor] = RunVar("ros_mobile_bridge.lag_monitor")


def current_monitor() -> LagMonitor:
    """The current event loop's monitor, created (empty, not sampling) on
    first use in this loop. Raises ``RuntimeError`` outside an event loop."""
    try:
        return _MONITOR.get()
    except LookupError:
        monitor = LagMonitor()
        _MONITOR.set(monitor)
        return monitor
    except RuntimeError:
        raise RuntimeError(
            "the lag monitor belongs to an event loop: call this from async code "
            "running on asyncio or trio (from a worker thread, go through "
            "anyio.from_thread.run_sync)"
        ) from None


async def participate() -> NoReturn:
    """Take part in sampling the current loop's lag, until cancelled.

    Each client runs this as one of its own tasks: the first client on a
    loop samples, and sampling stops with the last (see
    :meth:`LagMonitor.participate`)."""
    await current_monitor().participate()


# -- readers behind ``rmb.lag`` ------------------------------------------------------
def max_lag_ms() -> float:
    """The current event loop's largest lag over the last second, in ms
    (0.0 before any sample). Raises ``RuntimeError`` outside an event loop."""
    return current_monitor().max_lag_ms()


def recurring_lag_ms() -> float:
    """The highest lag at least three samples of the current event loop's
    last second reached, in ms (0.0 before three samples): the throttle's
    TIGHTEN signal. Raises ``RuntimeError`` outside an event loop."""
    return current_monitor().recurring_lag_ms()


def sustained_lag_ms() -> float:
    """The current event loop's 90th-percentile lag over the last four
    seconds, capped at what at least three samples reached, in ms (0.0
    before three samples). Raises ``RuntimeError`` outside
    an event loop."""
    return current_monitor().sustained_lag_ms()


def stats() -> LagStats:
    """:class:`LagStats` over the current event loop's kept history (about
    two minutes). Raises ``RuntimeError`` outside an event loop."""
    return current_monitor().stats()


def history_csv() -> str:
    """The current event loop's lag history as CSV (``time_s,lag_ms``, time
    in seconds since the oldest kept sample). Raises ``RuntimeError``
    outside an event loop."""
    return current_monitor().history_csv()


def clear() -> None:
    """Forget the current event loop's lag history (sampling goes on if a
    client is connected). Raises ``RuntimeError`` outside an event loop."""
    current_monitor().clear()
