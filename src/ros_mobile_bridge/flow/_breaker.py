"""The per-subscription circuit breaker: when the event loop stays saturated
even at the throttle's deepest bucket, stop delivering that subscription for
a cooldown, then probe.

States (:data:`BreakerState`)::

    closed --(saturated at the deepest bucket for dwell_s)--> tripped_auto
    tripped_auto --(cooldown over: observe()/poll())--------> half_open
    half_open --(healthy for probe_s)-----------------------> closed
    half_open --(saturated at the deepest bucket for dwell_s)> tripped_auto (next cooldown)
    any --(disable())---------------------------------------> tripped_manual
    tripped_auto / tripped_manual --(retry())---------------> half_open
    any --(reset(): the connection ended)-------------------> closed

*Saturated* means an observation with ``lag_ms >= saturation_ms`` while the
throttle sits at its deepest bucket. Observations are discrete: a dwell runs
from the first saturated observation to the current one, and any observation
that is not saturated restarts it. Half-open uses the same dwell rule as
closed (one spike does not re-trip a probing subscription), and it closes
once no saturated observation has been seen for ``probe_s``.

Cooldowns grow with each automatic trip within a connection
(``cooldowns_s``, the last one repeating: 30, 60, 120, 300, 300 s by
default); only :meth:`CircuitBreaker.reset` (the connection ended) starts the
ladder over. Breaker timers die with the connection.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from typing import Literal

from ._watch import Watchable, Watcher

__all__ = ["BreakerState", "CircuitBreaker"]

BreakerState = Literal["closed", "tripped_auto", "half_open", "tripped_manual"]
"""``"closed"``: delivering. ``"tripped_auto"``: stopped by saturation until
``next_retry_at``. ``"half_open"``: delivering again on probation.
``"tripped_manual"``: stopped by :meth:`CircuitBreaker.disable` until
:meth:`CircuitBreaker.retry`."""

Clock = Callable[[], float]


def _seconds(name: str, value: object, *, positive: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError(f"{name} must be a number, not {type(value).__name__}")
    number = float(value)
    if not math.isfinite(number) or number < 0 or (positive and number == 0):
        raise ValueError(f"{name} must be a finite number {'> 0' if positive else '>= 0'}")
    return number


class CircuitBreaker:
    """One subscription's breaker. Synchronous and clock-driven: the client
    calls :meth:`observe` every 100-250 ms with the current lag and whether
    the throttle is at its deepest bucket, and acts on the transitions it
    returns (``"tripped_*"``: stop delivering; ``"half_open"`` / ``"closed"``:
    deliver).

    ``clock`` returns monotonic seconds (injectable for exact tests).
    ``cooldowns_s``: the waits after successive automatic trips, the last
    repeating. ``saturation_ms``: the lag that counts as saturated.
    ``dwell_s``: how long saturation must last to trip. ``warmup_s``: after
    creation and after :meth:`reset`, no trip is considered for this long
    (observations during it are ignored, so the earliest trip is
    ``warmup_s + dwell_s`` in). ``probe_s``: how long half-open must stay
    unsaturated to close. Invalid values raise ``ValueError``/``TypeError``."""

    def __init__(
        self,
        *,
        clock: Clock = time.monotonic,
        cooldowns_s: Sequence[float] = (30.0, 60.0, 120.0, 300.0),
        saturation_ms: float = 250.0,
        dwell_s: float = 3.0,
        warmup_s: float = 5.0,
        probe_s: float = 5.0,
    ) -> None:
        if isinstance(cooldowns_s, str | bytes) or not isinstance(cooldowns_s, Sequence):
            raise TypeError("cooldowns_s must be a sequence of seconds")
        if not cooldowns_s:
            raise ValueError("cooldowns_s must not be empty")
        self._cooldowns = tuple(
            _seconds(f"cooldowns_s[{i}]", c, positive=True) for i, c in enumerate(cooldowns_s)
        )
        self._saturation_ms = _seconds("saturation_ms", saturation_ms, positive=True)
        self._dwell_s = _seconds("dwell_s", dwell_s)
        self._warmup_s = _seconds("warmup_s", warmup_s)
        self._probe_s = _seconds("probe_s", probe_s)
        self._clock = clock
        self._state: Watchable[BreakerState] = Watchable("closed")
        self._warm_until = clock() + self._warmup_s
        self._saturated_since: float | None = None
        self._healthy_since: float | None = None
        self._next_retry_at: float | None = None
        self._level = 0
        self._trips = 0

    # -- reading ---------------------------------------------------------------------
    @property
    def state(self) -> BreakerState:
        """The current state."""
        return self._state.value

    @property
    def next_retry_at(self) -> float | None:
        """When ``tripped_auto`` turns ``half_open``, in clock seconds
        (``time.monotonic`` by default); None in every other state."""
        return self._next_retry_at

    @property
    def trips(self) -> int:
        """Automatic trips over the breaker's life (:meth:`reset` keeps it)."""
        return self._trips

    @property
    def next_cooldown_s(self) -> float:
        """The cooldown the next automatic trip would get."""
        return self._cooldowns[min(self._level, len(self._cooldowns) - 1)]

    def watch(self) -> Watcher[BreakerState]:
        """Async iterator: the current state at once, then each new one.
        A watcher that falls behind sees the newest state (intermediate ones
        are coalesced). Ends when :meth:`close` is called."""
        return self._state.watch()

    # -- driving ---------------------------------------------------------------------
    def observe(self, lag_ms: float, at_deepest_bucket: bool) -> BreakerState | None:
        """Feed one observation; returns the new state on a transition, else
        None. In ``tripped_auto`` the lag is ignored and only the cooldown is
        checked (as :meth:`poll`); in ``tripped_manual`` nothing happens."""
        now = self._clock()
        state = self._state.value
        if state == "tripped_manual":
            return None
        if state == "tripped_auto":
            return self._half_open_if_due(now)
        if state == "closed" and now < self._warm_until:
            self._saturated_since = None
            return None
        if at_deepest_bucket and lag_ms >= self._saturation_ms:
            self._healthy_since = None
            if self._saturated_since is None:
                self._saturated_since = now
            if now - self._saturated_since >= self._dwell_s:
                return self._trip(now)
            return None
        self._saturated_since = None
        if state == "half_open":
            if self._healthy_since is None:
                self._healthy_since = now
            if now - self._healthy_since >= self._probe_s:
                self._healthy_since = None
                return self._set("closed")
        return None

    def poll(self) -> BreakerState | None:
        """Check the cooldown alone: ``tripped_auto`` becomes ``half_open``
        once ``clock() >= next_retry_at``. Returns the new state, else None."""
        if self._state.value == "tripped_auto":
            return self._half_open_if_due(self._clock())
        return None

    def retry(self) -> BreakerState | None:
        """Probe now: ``tripped_auto`` or ``tripped_manual`` becomes
        ``half_open`` (returned); in other states nothing happens (None)."""
        if self._state.value in ("tripped_auto", "tripped_manual"):
            return self._enter_half_open(self._clock())
        return None

    def disable(self) -> BreakerState | None:
        """Stop delivery until :meth:`retry` (or :meth:`reset`): the state
        becomes ``tripped_manual``, with no automatic retry. Returns it, or
        None if already there. Does not count as a trip."""
        if self._state.value == "tripped_manual":
            return None
        self._next_retry_at = None
        self._saturated_since = None
        self._healthy_since = None
        return self._set("tripped_manual")

    def reset(self) -> BreakerState | None:
        """The connection ended: back to ``closed`` from any state (a manual
        disable included), timers cleared, the cooldown ladder back to its
        first step and the warm-up restarted. Returns ``"closed"`` if the
        state changed, else None."""
        self._warm_until = self._clock() + self._warmup_s
        self._next_retry_at = None
        self._saturated_since = None
        self._healthy_since = None
        self._level = 0
        return self._set("closed")

    def close(self) -> None:
        """End every :meth:`watch` iterator (the subscription is gone)."""
        self._state.close()

    # -- transitions -----------------------------------------------------------------
    def _set(self, state: BreakerState) -> BreakerState | None:
        return state if self._state.set(state) else None

    def _trip(self, now: float) -> BreakerState | None:
        cooldown = self.next_cooldown_s
        self._level += 1
        self._trips += 1
        self._next_retry_at = now + cooldown
        self._saturated_since = None
        self._healthy_since = None
        return self._set("tripped_auto")

    def _half_open_if_due(self, now: float) -> BreakerState | None:
        due = self._next_retry_at
        if due is not None and now >= due:
            return self._enter_half_open(now)
        return None

    def _enter_half_open(self, now: float) -> BreakerState | None:
        self._next_retry_at = None
        self._saturated_since = None
        self._healthy_since = now
        return self._set("half_open")
