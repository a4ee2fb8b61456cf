"""Readers of the current event loop's lag monitor, for diagnostics.

The monitor samples how late the event loop wakes from a short sleep; the
adaptive throttle and the circuit breaker act on it. It samples while at
least one client is open on the loop, and keeps about two minutes of
history::

    import ros_mobile_bridge as rmb

    print(f"max loop lag over the last second: {rmb.lag.max_lag_ms():.1f} ms")
    print(f"lag the throttle acts on: {rmb.lag.recurring_lag_ms():.1f} ms")
    print(rmb.lag.stats())          # LagStats(p50_ms, p90_ms, p99_ms, max_ms, count)
    report = rmb.lag.history_csv()  # "time_s,lag_ms\\n..." for bug reports

Each event loop has its own monitor. Every reader must be called from async
code running on that loop (asyncio or trio); outside an event loop it raises
``RuntimeError`` rather than answering for no loop in particular.
"""

from __future__ import annotations

from .flow._lag import LagStats as LagStats
from .flow._lag import clear as clear
from .flow._lag import history_csv as history_csv
from .flow._lag import max_lag_ms as max_lag_ms
from .flow._lag import recurring_lag_ms as recurring_lag_ms
from .flow._lag import stats as stats
from .flow._lag import sustained_lag_ms as sustained_lag_ms

__all__ = [
    "LagStats",
    "clear",
    "history_csv",
    "max_lag_ms",
    "recurring_lag_ms",
    "stats",
    "sustained_lag_ms",
]
