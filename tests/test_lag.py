"""The event-loop lag monitor: exact window semantics with a fake clock, the
per-loop registry with sampler leadership (asyncio and trio), and the public
``rmb.lag`` readers.

Window tests feed samples by hand with explicit times. Sampler tests run the
real sampler with a tiny interval and wait (with a deadline) for samples to
arrive; they assert behaviours (who samples, whether sampling goes on), never
durations."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any, NoReturn

import anyio
import pytest

from _util import wait_until
from ros_mobile_bridge import lag
from ros_mobile_bridge.flow._lag import LagMonitor, LagStats, current_monitor, participate


class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now


class CountingMonitor(LagMonitor):
    """Counts how many sampler loops run at once."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.running = 0
        self.most_running = 0
        self.runs = 0

    async def run(self) -> NoReturn:
        self.running += 1
        self.runs += 1
        self.most_running = max(self.most_running, self.running)
        try:
            await super().run()
        finally:
            self.running -= 1


SAMPLED = 10.0
"""Seconds to wait for a sampler-driven condition (the sampler ticks on real time)."""


# -- window semantics (fake clock) ------------------------------------------------------
def test_signals_are_zero_without_samples() -> None:
    monitor = LagMonitor(clock=FakeClock())
    assert monitor.max_lag_ms() == 0.0
    assert monitor.sustained_lag_ms() == 0.0
    assert monitor.stats() == LagStats(0.0, 0.0, 0.0, 0.0, 0)
    assert len(monitor) == 0


def test_max_lag_covers_the_last_second_and_drops_older_samples() -> None:
    monitor = LagMonitor(clock=FakeClock())
    monitor.record(100.0, now=0.0)
    monitor.record(10.0, now=0.5)
    assert monitor.max_lag_ms() == 100.0
    monitor.record(20.0, now=0.95)
    assert monitor.max_lag_ms() == 100.0  # 0.95 s old: still inside
    monitor.record(5.0, now=1.0)
    assert monitor.max_lag_ms() == 20.0  # the spike at 0.0 is exactly 1 s old: out
    monitor.record(1.0, now=1.96)
    assert monitor.max_lag_ms() == 5.0  # 0.5 and 0.95 are out; 1.0 is 0.96 s old
    monitor.record(0.0, now=2.0)
    assert monitor.max_lag_ms() == 1.0  # 1.0 is exactly 1 s old: out


def test_max_lag_rises_at_once_with_a_spike() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(10):
        monitor.record(2.0, now=i * 0.05)
    assert monitor.max_lag_ms() == 2.0
    monitor.record(400.0, now=0.5)
    assert monitor.max_lag_ms() == 400.0


def test_max_lag_tracks_the_window_maximum_exactly() -> None:
    monitor = LagMonitor(clock=FakeClock())
    values = [5.0, 50.0, 3.0, 40.0, 1.0, 30.0, 2.0, 2.0, 60.0, 1.0, 0.0, 7.0]
    for i, value in enumerate(values):
        now = i * 0.25  # four samples per second: the window holds the last four
        monitor.record(value, now=now)
        assert monitor.max_lag_ms() == max(values[max(0, i - 3) : i + 1])


def test_sustained_lag_is_the_p90_of_the_last_four_seconds() -> None:
    monitor = LagMonitor(clock=FakeClock())
    # 40 samples, 0.1 s apart (t = 0.0 .. 3.9): lags 1..40
    for i in range(40):
        monitor.record(float(i + 1), now=i * 0.1)
    # nearest rank: ceil(0.9 * 40) = 36th smallest
    assert monitor.sustained_lag_ms() == 36.0
    # at t = 4.0 the sample at t = 0.0 (lag 1) leaves; 40 samples 2..40 and 0
    monitor.record(0.0, now=4.0)
    assert monitor.sustained_lag_ms() == 36.0
    # at t = 8.0 everything older than 4 s is gone: one sample is not
    # sustained; three are
    monitor.record(3.0, now=8.0)
    assert monitor.sustained_lag_ms() == 0.0
    monitor.record(5.0, now=8.1)
    assert monitor.sustained_lag_ms() == 0.0
    monitor.record(4.0, now=8.2)
    assert monitor.sustained_lag_ms() == 3.0  # what all three reached


def test_sustained_lag_ignores_a_single_spike() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(80):
        monitor.record(400.0 if i == 40 else 2.0, now=i * 0.05)
    assert monitor.max_lag_ms() == 2.0  # the spike was 2 s ago
    assert monitor.sustained_lag_ms() == 2.0
    monitor.record(400.0, now=4.0)
    assert monitor.max_lag_ms() == 400.0
    assert monitor.sustained_lag_ms() == 2.0


def test_sustained_lag_needs_three_samples_even_in_a_short_window() -> None:
    # 10 samples: the p90 would be the 9th smallest (the 2nd largest), but
    # only what three samples reached counts
    monitor = LagMonitor(clock=FakeClock())
    for i in range(10):
        monitor.record(500.0 if i in (3, 7) else 1.0, now=i * 0.1)
    assert monitor.sustained_lag_ms() == 1.0
    monitor.record(400.0, now=1.0)
    assert monitor.sustained_lag_ms() == 400.0


def test_recurring_lag_needs_three_samples_of_the_last_second() -> None:
    monitor = LagMonitor(clock=FakeClock())
    monitor.record(300.0, now=0.0)
    monitor.record(300.0, now=0.05)
    assert monitor.recurring_lag_ms() == 0.0  # fewer than three samples
    monitor.record(5.0, now=0.1)
    assert monitor.recurring_lag_ms() == 5.0  # 300, 300, 5: three reached 5
    monitor.record(200.0, now=0.15)
    assert monitor.recurring_lag_ms() == 200.0  # 300, 300, 200
    assert monitor.max_lag_ms() == 300.0


def test_one_stall_moves_the_max_but_never_the_recurring_or_sustained_lag() -> None:
    monitor = LagMonitor(clock=FakeClock())
    t = 0.0
    for _ in range(80):  # a calm loop: 2 ms lag every 50 ms
        t += 0.052
        monitor.record(2.0, now=t)
    t += 1.0  # user code blocked the loop for a second
    monitor.record(1000.0, now=t)
    assert monitor.max_lag_ms() == 1000.0
    assert monitor.recurring_lag_ms() == 2.0
    assert monitor.sustained_lag_ms() == 2.0
    for _ in range(30):  # the backlog is handled: calm again
        t += 0.052
        monitor.record(2.0, now=t)
        assert monitor.recurring_lag_ms() == 2.0
        assert monitor.sustained_lag_ms() == 2.0


def test_two_stalls_in_a_row_are_not_sustained_either() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(20):
        monitor.record(1.0, now=i * 0.05)
    monitor.record(55.0, now=1.1)  # a decoder build
    monitor.record(60.0, now=1.2)  # another subscriber's
    assert monitor.recurring_lag_ms() == 1.0
    assert monitor.sustained_lag_ms() == 1.0


def test_a_loop_sampled_less_than_three_times_a_second_still_shows_recurring_lag() -> None:
    # 500 ms lag per sample: samples 0.55 s apart, two per second; the
    # window reaches back to the newest three
    monitor = LagMonitor(clock=FakeClock())
    monitor.record(500.0, now=0.55)
    monitor.record(500.0, now=1.10)
    assert monitor.recurring_lag_ms() == 0.0
    monitor.record(500.0, now=1.65)
    assert monitor.recurring_lag_ms() == 500.0


def test_clear_also_zeroes_the_recurring_lag() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(3):
        monitor.record(100.0, now=i * 0.1)
    assert monitor.recurring_lag_ms() == 100.0
    monitor.clear()
    assert monitor.recurring_lag_ms() == 0.0
    monitor.record(100.0, now=1.0)
    assert monitor.recurring_lag_ms() == 0.0


def test_history_is_trimmed_to_history_seconds() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for second in range(131):  # t = 0 .. 130
        monitor.record(float(second), now=float(second))
    # kept while younger than 120 s: t = 11 .. 130
    assert len(monitor) == 120
    assert monitor.stats().count == 120
    assert monitor.history_csv().splitlines()[1] == "0.000,11.000"


def test_history_is_kept_while_no_one_samples() -> None:
    monitor = LagMonitor(clock=FakeClock(1000.0))
    monitor.record(5.0, now=0.0)
    # the clock moving on does not trim: only new samples do
    assert monitor.stats().count == 1


def test_stats_use_nearest_rank_percentiles() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(100):
        monitor.record(float(100 - i), now=i * 0.05)  # lags 100 .. 1, order irrelevant
    assert monitor.stats() == LagStats(
        p50_ms=50.0, p90_ms=90.0, p99_ms=99.0, max_ms=100.0, count=100
    )
    small = LagMonitor(clock=FakeClock())
    for i, value in enumerate([3.0, 1.0, 2.0]):
        small.record(value, now=float(i))
    assert small.stats() == LagStats(p50_ms=2.0, p90_ms=3.0, p99_ms=3.0, max_ms=3.0, count=3)


def test_negative_and_nan_lags_count_as_zero() -> None:
    monitor = LagMonitor(clock=FakeClock())
    monitor.record(-5.0, now=0.0)
    monitor.record(float("nan"), now=0.1)
    assert monitor.max_lag_ms() == 0.0
    assert monitor.stats() == LagStats(0.0, 0.0, 0.0, 0.0, 2)


def test_a_time_going_back_is_taken_as_the_newest_time() -> None:
    monitor = LagMonitor(clock=FakeClock())
    monitor.record(1.0, now=5.0)
    monitor.record(2.0, now=4.0)
    assert monitor.history_csv() == "time_s,lag_ms\n0.000,1.000\n0.000,2.000\n"


def test_record_without_a_time_reads_the_clock() -> None:
    clock = FakeClock(10.0)
    monitor = LagMonitor(clock=clock)
    monitor.record(50.0)
    clock.now = 11.5
    monitor.record(1.0)
    assert monitor.max_lag_ms() == 1.0  # the first sample is 1.5 s old
    assert monitor.history_csv() == "time_s,lag_ms\n0.000,50.000\n1.500,1.000\n"


def test_history_csv_format() -> None:
    monitor = LagMonitor(clock=FakeClock())
    assert monitor.history_csv() == "time_s,lag_ms\n"
    monitor.record(1.25, now=100.0)
    monitor.record(0.0, now=100.05)
    monitor.record(12.3456, now=101.0)
    assert monitor.history_csv() == ("time_s,lag_ms\n0.000,1.250\n0.050,0.000\n1.000,12.346\n")


def test_clear_forgets_samples_and_zeroes_the_signals() -> None:
    monitor = LagMonitor(clock=FakeClock())
    for i in range(10):
        monitor.record(100.0, now=i * 0.05)
    monitor.clear()
    assert monitor.max_lag_ms() == 0.0
    assert monitor.sustained_lag_ms() == 0.0
    assert monitor.stats().count == 0
    assert monitor.history_csv() == "time_s,lag_ms\n"
    monitor.record(3.0, now=1.0)
    assert monitor.max_lag_ms() == 3.0
    assert monitor.sustained_lag_ms() == 0.0  # the old samples do not count
    monitor.record(3.0, now=1.05)
    monitor.record(3.0, now=1.1)
    assert monitor.sustained_lag_ms() == 3.0


@pytest.mark.parametrize(
    "kwargs",
    [
        {"interval": 0},
        {"interval": -1.0},
        {"history_seconds": 0},
        {"history_seconds": float("inf")},
        {"max_window_s": float("nan")},
        {"sustained_window_s": -4.0},
    ],
)
def test_invalid_settings_raise_value_error(kwargs: dict[str, Any]) -> None:
    with pytest.raises(ValueError, match=next(iter(kwargs))):
        LagMonitor(**kwargs)


def test_a_non_number_setting_raises_type_error() -> None:
    with pytest.raises(TypeError, match="interval"):
        LagMonitor(interval="fast")  # type: ignore[arg-type]


# -- the sampler and its leadership (asyncio and trio) ---------------------------------------
async def test_the_sampler_records_on_the_real_loop() -> None:
    monitor = LagMonitor(interval=0.001)
    async with anyio.create_task_group() as tg:
        tg.start_soon(monitor.run)
        await wait_until(lambda: len(monitor) >= 3, SAMPLED)
        tg.cancel_scope.cancel()
    assert all(s >= 0.0 for s in (monitor.stats().p50_ms, monitor.max_lag_ms()))


async def test_two_participants_on_one_loop_make_one_sampler() -> None:
    monitor = CountingMonitor(interval=0.001)
    async with anyio.create_task_group() as tg:
        tg.start_soon(monitor.participate)
        tg.start_soon(monitor.participate)
        await wait_until(lambda: len(monitor) >= 5, SAMPLED)
        assert monitor.participants == 2
        assert monitor.sampling
        assert monitor.running == 1
        tg.cancel_scope.cancel()
    assert monitor.most_running == 1
    assert monitor.runs == 1
    assert monitor.participants == 0
    assert not monitor.sampling


async def test_another_participant_takes_over_when_the_sampler_leaves() -> None:
    monitor = CountingMonitor(interval=0.001)
    async with anyio.create_task_group() as tg:
        first = anyio.CancelScope()
        second = anyio.CancelScope()

        async def member(scope: anyio.CancelScope) -> None:
            with scope:
                await monitor.participate()

        tg.start_soon(member, first)
        await wait_until(lambda: monitor.sampling, SAMPLED)
        tg.start_soon(member, second)
        await wait_until(lambda: monitor.participants == 2, SAMPLED)
        assert monitor.runs == 1  # the first samples, the second waits

        first.cancel()  # the sampling participant's client closes
        await wait_until(lambda: monitor.participants == 1, SAMPLED)
        before = len(monitor)
        await wait_until(lambda: len(monitor) >= before + 3, SAMPLED)  # sampling goes on
        assert monitor.runs == 2
        assert monitor.most_running == 1
        assert monitor.sampling

        second.cancel()  # the last participant leaves
        await wait_until(lambda: monitor.participants == 0, SAMPLED)
        assert (monitor.sampling, monitor.running) == (False, 0)
    kept = len(monitor)
    assert kept > 0  # the history stays readable
    await anyio.sleep(0.02)  # several intervals: nothing samples any more
    assert len(monitor) == kept


async def test_a_waiting_participant_leaving_does_not_stop_the_sampler() -> None:
    monitor = CountingMonitor(interval=0.001)
    async with anyio.create_task_group() as tg:
        waiting = anyio.CancelScope()

        async def member(scope: anyio.CancelScope) -> None:
            with scope:
                await monitor.participate()

        tg.start_soon(monitor.participate)
        await wait_until(lambda: monitor.sampling, SAMPLED)
        tg.start_soon(member, waiting)
        await wait_until(lambda: monitor.participants == 2, SAMPLED)
        waiting.cancel()
        await wait_until(lambda: monitor.participants == 1, SAMPLED)
        before = len(monitor)
        await wait_until(lambda: len(monitor) >= before + 3, SAMPLED)
        assert monitor.runs == 1
        tg.cancel_scope.cancel()


async def test_the_signals_start_over_after_nobody_sampled_but_not_on_a_handover() -> None:
    """The signals describe the loop while it was watched without a break: a
    new sampler after the last participant left starts them over (the
    history stays), a hand-over between participants keeps them."""
    # windows of a minute: the stalls stay inside them however slow the host
    monitor = CountingMonitor(interval=0.002, max_window_s=60.0, sustained_window_s=60.0)
    stall = 10_000.0  # ms: no real sample of this test comes near it
    for _ in range(3):
        monitor.record(stall)  # three stalls a moment ago
    assert monitor.recurring_lag_ms() == monitor.sustained_lag_ms() == stall

    async def member(scope: anyio.CancelScope) -> None:
        with scope:
            await monitor.participate()

    async with anyio.create_task_group() as tg:
        first, second = anyio.CancelScope(), anyio.CancelScope()
        tg.start_soon(member, first)
        await wait_until(lambda: monitor.sampling, SAMPLED)
        tg.start_soon(member, second)
        await wait_until(lambda: monitor.participants == 2, SAMPLED)
        first.cancel()  # a hand-over: the second samples on, the signals stay
        await wait_until(lambda: monitor.runs == 2, SAMPLED)
        before = len(monitor)
        await wait_until(lambda: len(monitor) > before, SAMPLED)
        assert monitor.recurring_lag_ms() == stall  # (the calm samples dilute the p90)
        second.cancel()  # the last participant leaves
        await wait_until(lambda: monitor.participants == 0, SAMPLED)
    assert monitor.recurring_lag_ms() == stall  # still readable while nobody samples
    kept = len(monitor)

    async with anyio.create_task_group() as tg:
        tg.start_soon(monitor.participate)  # a new client, on a calm loop
        await wait_until(lambda: len(monitor) >= kept + 1, SAMPLED)
        # only the new samples count (the stalls are well inside every window)
        assert monitor.max_lag_ms() < stall
        assert monitor.recurring_lag_ms() < stall
        assert monitor.sustained_lag_ms() < stall
        await wait_until(lambda: len(monitor) >= kept + 5, SAMPLED)
        assert monitor.sustained_lag_ms() < stall
        tg.cancel_scope.cancel()
    assert monitor.stats().max_ms == stall  # the history kept the stalls


async def test_a_blocked_loop_shows_up_as_lag() -> None:
    monitor = LagMonitor(interval=0.05)
    async with anyio.create_task_group() as tg:
        tg.start_soon(monitor.participate)
        await wait_until(lambda: len(monitor) >= 1, SAMPLED)
        time.sleep(0.2)  # block the event loop on purpose
        # the sampler was asleep (0.05 s) when the loop blocked for 0.2 s
        await wait_until(lambda: monitor.stats().max_ms >= 145.0, SAMPLED)
        assert monitor.max_lag_ms() >= 145.0
        tg.cancel_scope.cancel()


# -- the shared tick -----------------------------------------------------------------------
async def test_tick_callbacks_run_in_the_one_sampler_and_survive_a_handover(
    caplog: pytest.LogCaptureFixture,
) -> None:
    """Every registered callback runs on each tick, in the sampling task (one
    sampler however many participants); a failing one is logged and the
    others still run; a removed one stops; the ticks go on after the sampling
    participant leaves."""
    monitor = CountingMonitor(interval=0.001, tick_interval=0.005)
    calls = {"a": 0, "b": 0, "bad": 0}

    def bad() -> None:
        calls["bad"] += 1
        raise RuntimeError("a bug in one client")

    keys = {
        "a": monitor.add_tick(lambda: calls.__setitem__("a", calls["a"] + 1)),
        "bad": monitor.add_tick(bad),
        "b": monitor.add_tick(lambda: calls.__setitem__("b", calls["b"] + 1)),
    }
    assert monitor.ticks == 3
    async with anyio.create_task_group() as tg:
        first = anyio.CancelScope()

        async def member(scope: anyio.CancelScope) -> None:
            with scope:
                await monitor.participate()

        tg.start_soon(member, first)
        await wait_until(lambda: monitor.sampling, SAMPLED)  # the first one samples
        tg.start_soon(monitor.participate)
        await wait_until(lambda: monitor.participants == 2, SAMPLED)
        await wait_until(lambda: calls["a"] >= 3, SAMPLED)
        assert calls["b"] >= calls["a"] - 1  # the failing one between them did not stop it
        assert calls["bad"] >= 3
        assert any("periodic callback failed" in r.getMessage() for r in caplog.records)
        assert monitor.most_running == 1

        first.cancel()  # the sampler's client leaves: the other takes over
        await wait_until(lambda: monitor.runs == 2, SAMPLED)
        monitor.remove_tick(keys["a"])
        monitor.remove_tick(keys["a"])  # twice is harmless
        a, b = calls["a"], calls["b"]
        await wait_until(lambda: calls["b"] >= b + 3, SAMPLED)
        assert calls["a"] == a  # removed: no more calls
        tg.cancel_scope.cancel()
    assert monitor.ticks == 2


async def test_without_a_participant_no_tick_runs() -> None:
    monitor = LagMonitor(interval=0.001, tick_interval=0.002)
    calls: list[int] = []
    monitor.add_tick(lambda: calls.append(1))
    await anyio.sleep(0.02)
    assert calls == []


def test_tick_interval_must_be_positive() -> None:
    with pytest.raises(ValueError, match="tick_interval"):
        LagMonitor(tick_interval=0)


# -- one monitor per loop, and the rmb.lag readers ---------------------------------------------
async def test_current_monitor_is_one_per_loop() -> None:
    assert current_monitor() is current_monitor()


def test_each_event_loop_gets_its_own_monitor() -> None:
    async def record_and_read(lag_ms: float) -> int:
        before = lag.stats().count
        current_monitor().record(lag_ms)
        return before

    assert anyio.run(record_and_read, 5.0) == 0
    assert anyio.run(record_and_read, 5.0) == 0  # a new loop starts empty


async def test_participate_samples_the_current_loop() -> None:
    async with anyio.create_task_group() as tg:
        tg.start_soon(participate)
        tg.start_soon(participate)
        monitor = current_monitor()
        await wait_until(lambda: monitor.participants == 2 and len(monitor) >= 1, SAMPLED)
        assert monitor.sampling
        tg.cancel_scope.cancel()
    assert current_monitor().participants == 0
    assert lag.stats().count >= 1


async def test_public_readers_read_the_current_loop_monitor() -> None:
    monitor = current_monitor()
    assert lag.max_lag_ms() == 0.0
    assert lag.recurring_lag_ms() == 0.0
    assert lag.sustained_lag_ms() == 0.0
    assert lag.stats() == lag.LagStats(0.0, 0.0, 0.0, 0.0, 0)
    assert lag.history_csv() == "time_s,lag_ms\n"
    monitor.record(12.0, now=0.0)
    monitor.record(30.0, now=0.05)
    monitor.record(20.0, now=0.10)
    assert lag.max_lag_ms() == 30.0
    assert lag.recurring_lag_ms() == 12.0
    assert lag.sustained_lag_ms() == 12.0
    assert lag.stats() == lag.LagStats(20.0, 30.0, 30.0, 30.0, 3)
    assert lag.history_csv() == "time_s,lag_ms\n0.000,12.000\n0.050,30.000\n0.100,20.000\n"
    lag.clear()
    assert lag.stats().count == 0
    assert lag.max_lag_ms() == 0.0
    assert lag.recurring_lag_ms() == 0.0


@pytest.mark.parametrize(
    "reader",
    [
        lag.max_lag_ms,
        lag.recurring_lag_ms,
        lag.sustained_lag_ms,
        lag.stats,
        lag.history_csv,
        lag.clear,
    ],
    ids=lambda f: f.__name__,
)
def test_readers_outside_an_event_loop_raise_runtime_error(reader: Callable[[], object]) -> None:
    with pytest.raises(RuntimeError, match="event loop"):
        reader()


def test_the_public_module_exports_exactly_the_readers() -> None:
    assert sorted(lag.__all__) == [
        "LagStats",
        "clear",
        "history_csv",
        "max_lag_ms",
        "recurring_lag_ms",
        "stats",
        "sustained_lag_ms",
    ]
    for name in lag.__all__:
        assert getattr(lag, name).__doc__
