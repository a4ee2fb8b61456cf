"""The circuit breaker: warm-up, dwell, the cooldown ladder, half-open
probing, manual retry/disable, reset with the connection, and watch().

Time is a fake clock moved by hand; observations come every 0.1 s as the
client would send them. Every assertion is exact."""

from __future__ import annotations

import anyio
import pytest

from ros_mobile_bridge.flow._breaker import BreakerState, CircuitBreaker

SATURATED = 300.0  # above the default 250 ms saturation
HEALTHY = 20.0
STEP = 0.1


class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now


def ticks(start: float, stop: float) -> list[float]:
    """Observation times from ``start`` up to and including ``stop``, every STEP
    (computed from integers so the times are exact decimals)."""
    first, last = round(start / STEP), round(stop / STEP)
    return [round(i * STEP, 6) for i in range(first, last + 1)]


def drive(
    breaker: CircuitBreaker,
    clock: FakeClock,
    start: float,
    stop: float,
    lag_ms: float,
    *,
    at_deepest: bool = True,
) -> list[tuple[float, BreakerState]]:
    """Observe from ``start`` to ``stop``; the transitions with their times."""
    transitions: list[tuple[float, BreakerState]] = []
    for now in ticks(start, stop):
        clock.now = now
        state = breaker.observe(lag_ms, at_deepest)
        if state is not None:
            transitions.append((now, state))
    return transitions


def tripped_breaker(
    cooldowns_s: tuple[float, ...] = (30.0, 60.0, 120.0, 300.0),
) -> tuple[CircuitBreaker, FakeClock]:
    """A breaker that tripped at t = 8.0 (warm-up 5 s, then a 3 s dwell)."""
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, cooldowns_s=cooldowns_s)
    assert drive(breaker, clock, 0.0, 8.0, SATURATED) == [(8.0, "tripped_auto")]
    return breaker, clock


# -- closed -> tripped_auto ------------------------------------------------------------
def test_a_new_breaker_is_closed() -> None:
    breaker = CircuitBreaker(clock=FakeClock())
    assert breaker.state == "closed"
    assert breaker.next_retry_at is None
    assert breaker.trips == 0
    assert breaker.next_cooldown_s == 30.0


def test_no_trip_during_the_warm_up() -> None:
    clock = FakeClock(100.0)
    breaker = CircuitBreaker(clock=clock)
    assert drive(breaker, clock, 100.0, 104.9, 10_000.0) == []
    assert breaker.state == "closed"


def test_the_dwell_starts_when_the_warm_up_ends() -> None:
    clock = FakeClock(100.0)
    breaker = CircuitBreaker(clock=clock)
    # saturated from the start: the dwell counts from 105.0 (end of warm-up)
    assert drive(breaker, clock, 100.0, 110.0, SATURATED) == [(108.0, "tripped_auto")]
    assert breaker.next_retry_at == 138.0
    assert breaker.trips == 1


def test_no_trip_when_the_throttle_is_not_at_its_deepest_bucket() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock)
    assert drive(breaker, clock, 0.0, 60.0, 10_000.0, at_deepest=False) == []
    assert breaker.state == "closed"


def test_trips_after_the_dwell_at_the_deepest_bucket() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, warmup_s=0.0)
    assert drive(breaker, clock, 0.0, 2.9, SATURATED) == []
    clock.now = 3.0
    assert breaker.observe(SATURATED, True) == "tripped_auto"
    assert breaker.state == "tripped_auto"
    assert breaker.next_retry_at == 33.0


def test_a_lag_exactly_at_saturation_counts() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, warmup_s=0.0)
    assert drive(breaker, clock, 0.0, 3.0, 250.0) == [(3.0, "tripped_auto")]


def test_a_lag_dropping_below_saturation_restarts_the_dwell() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, warmup_s=0.0)
    assert drive(breaker, clock, 0.0, 2.5, SATURATED) == []
    assert drive(breaker, clock, 2.6, 2.6, 249.9) == []
    assert drive(breaker, clock, 2.7, 5.6, SATURATED) == []
    assert drive(breaker, clock, 5.7, 5.7, SATURATED) == [(5.7, "tripped_auto")]


def test_leaving_the_deepest_bucket_restarts_the_dwell() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, warmup_s=0.0)
    assert drive(breaker, clock, 0.0, 2.5, SATURATED) == []
    assert drive(breaker, clock, 2.6, 2.6, SATURATED, at_deepest=False) == []
    assert drive(breaker, clock, 2.7, 6.0, SATURATED) == [(5.7, "tripped_auto")]


# -- tripped_auto -> half_open -----------------------------------------------------------
def test_tripped_auto_ignores_the_lag_until_the_cooldown_ends() -> None:
    breaker, clock = tripped_breaker()
    assert breaker.next_retry_at == 38.0
    assert drive(breaker, clock, 8.1, 37.9, HEALTHY) == []
    assert breaker.state == "tripped_auto"
    clock.now = 38.0
    assert breaker.observe(SATURATED, True) == "half_open"
    assert breaker.next_retry_at is None


def test_poll_turns_half_open_when_the_cooldown_is_over() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 37.999
    assert breaker.poll() is None
    clock.now = 38.0
    assert breaker.poll() == "half_open"
    assert breaker.poll() is None  # only tripped_auto polls


def test_cooldowns_grow_30_60_120_300_then_stay_at_300() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock)
    cooldowns: list[float] = []
    now = 0.0
    for _ in range(6):
        transitions = drive(breaker, clock, now, now + 10.0, SATURATED)
        assert transitions[-1][1] == "tripped_auto"
        tripped_at = transitions[-1][0]
        assert breaker.next_retry_at is not None
        cooldowns.append(round(breaker.next_retry_at - tripped_at, 6))
        clock.now = breaker.next_retry_at
        assert breaker.poll() == "half_open"
        now = clock.now
    assert cooldowns == [30.0, 60.0, 120.0, 300.0, 300.0, 300.0]
    assert breaker.trips == 6


def test_custom_cooldowns() -> None:
    breaker, _ = tripped_breaker(cooldowns_s=(1.0, 2.0))
    assert breaker.next_retry_at == 9.0
    assert breaker.next_cooldown_s == 2.0


# -- half_open ------------------------------------------------------------------------------
def test_half_open_closes_after_probe_seconds_of_health() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 38.0
    assert breaker.poll() == "half_open"
    assert drive(breaker, clock, 38.1, 42.9, HEALTHY) == []
    assert breaker.state == "half_open"
    assert drive(breaker, clock, 43.0, 43.0, HEALTHY) == [(43.0, "closed")]
    assert breaker.next_retry_at is None


def test_a_saturated_blip_restarts_the_probe() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 38.0
    breaker.poll()
    assert drive(breaker, clock, 38.1, 41.0, HEALTHY) == []
    assert drive(breaker, clock, 41.1, 41.1, SATURATED) == []  # one blip: no re-trip
    assert drive(breaker, clock, 41.2, 46.1, HEALTHY) == []
    assert drive(breaker, clock, 46.2, 46.2, HEALTHY) == [(46.2, "closed")]


def test_half_open_trips_again_on_saturation_with_the_next_cooldown() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 38.0
    breaker.poll()
    # no warm-up in half-open: the same 3 s dwell from the first saturated observation
    assert drive(breaker, clock, 38.0, 42.0, SATURATED) == [(41.0, "tripped_auto")]
    assert breaker.next_retry_at == 101.0  # 60 s
    assert breaker.trips == 2


def test_the_ladder_keeps_growing_after_a_successful_probe() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 38.0
    breaker.poll()
    assert drive(breaker, clock, 38.1, 43.0, HEALTHY) == [(43.0, "closed")]
    # closed again, no new warm-up: the next trip gets the next cooldown
    assert drive(breaker, clock, 43.1, 47.0, SATURATED) == [(46.1, "tripped_auto")]
    assert breaker.next_retry_at == pytest.approx(106.1)


# -- manual controls -----------------------------------------------------------------------------
def test_retry_probes_at_once_from_tripped_auto() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 10.0
    assert breaker.retry() == "half_open"
    assert breaker.next_retry_at is None
    assert drive(breaker, clock, 10.1, 15.0, HEALTHY) == [(15.0, "closed")]


def test_retry_does_nothing_when_delivering() -> None:
    breaker = CircuitBreaker(clock=FakeClock())
    assert breaker.retry() is None
    assert breaker.state == "closed"


def test_disable_stops_delivery_with_no_automatic_retry() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock)
    assert breaker.disable() == "tripped_manual"
    assert breaker.next_retry_at is None
    assert drive(breaker, clock, 0.0, 1000.0, HEALTHY) == []
    clock.now = 100_000.0
    assert breaker.poll() is None
    assert breaker.state == "tripped_manual"
    assert breaker.trips == 0  # a manual stop is not a trip
    assert breaker.disable() is None
    assert breaker.retry() == "half_open"


def test_disable_cancels_a_pending_automatic_retry() -> None:
    breaker, clock = tripped_breaker()
    assert breaker.disable() == "tripped_manual"
    assert breaker.next_retry_at is None
    clock.now = 1000.0
    assert breaker.observe(HEALTHY, False) is None
    assert breaker.state == "tripped_manual"


# -- reset (the connection ended) ----------------------------------------------------------------
def test_reset_closes_and_clears_the_timers_and_the_ladder() -> None:
    breaker, clock = tripped_breaker()
    clock.now = 38.0
    breaker.poll()
    assert drive(breaker, clock, 38.0, 41.0, SATURATED)[-1] == (41.0, "tripped_auto")
    assert breaker.next_cooldown_s == 120.0
    clock.now = 50.0
    assert breaker.reset() == "closed"
    assert breaker.next_retry_at is None
    assert breaker.next_cooldown_s == 30.0
    assert breaker.trips == 2  # the lifetime count stays
    # the warm-up restarts: saturated from 50.0, the dwell counts from 55.0
    assert drive(breaker, clock, 50.0, 60.0, SATURATED) == [(58.0, "tripped_auto")]
    assert breaker.next_retry_at == 88.0


def test_reset_of_a_closed_breaker_restarts_the_warm_up() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock)
    assert drive(breaker, clock, 0.0, 7.0, SATURATED) == []  # dwell under way
    assert breaker.reset() is None  # already closed
    assert drive(breaker, clock, 7.1, 15.0, SATURATED) == [(15.0, "tripped_auto")]


def test_reset_clears_a_manual_disable() -> None:
    breaker = CircuitBreaker(clock=FakeClock())
    breaker.disable()
    assert breaker.reset() == "closed"


# -- validation ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "error"),
    [
        ({"cooldowns_s": ()}, ValueError),
        ({"cooldowns_s": (30.0, 0.0)}, ValueError),
        ({"cooldowns_s": (float("inf"),)}, ValueError),
        ({"cooldowns_s": "30"}, TypeError),
        ({"saturation_ms": 0.0}, ValueError),
        ({"dwell_s": -1.0}, ValueError),
        ({"warmup_s": float("nan")}, ValueError),
        ({"probe_s": "5"}, TypeError),
    ],
)
def test_invalid_settings_raise(kwargs: dict[str, object], error: type[Exception]) -> None:
    with pytest.raises(error):
        CircuitBreaker(clock=FakeClock(), **kwargs)  # type: ignore[arg-type]


def test_zero_dwell_and_warm_up_trip_on_the_first_saturated_observation() -> None:
    breaker = CircuitBreaker(clock=FakeClock(), dwell_s=0.0, warmup_s=0.0)
    assert breaker.observe(SATURATED, True) == "tripped_auto"


# -- watch (asyncio and trio) -------------------------------------------------------------------
async def test_watch_sees_the_current_state_then_each_transition_in_order() -> None:
    clock = FakeClock()
    breaker = CircuitBreaker(clock=clock, dwell_s=0.0, warmup_s=0.0, probe_s=1.0)
    first: list[BreakerState] = []
    second: list[BreakerState] = []

    async def watch(into: list[BreakerState]) -> None:
        async for state in breaker.watch():
            into.append(state)

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch, first)
        tg.start_soon(watch, second)
        await anyio.wait_all_tasks_blocked()
        assert breaker.observe(SATURATED, True) == "tripped_auto"
        await anyio.wait_all_tasks_blocked()
        clock.now = 30.0
        assert breaker.poll() == "half_open"
        await anyio.wait_all_tasks_blocked()
        clock.now = 31.0
        assert breaker.observe(HEALTHY, True) == "closed"
        await anyio.wait_all_tasks_blocked()
        assert breaker.disable() == "tripped_manual"
        await anyio.wait_all_tasks_blocked()
        assert breaker.retry() == "half_open"
        await anyio.wait_all_tasks_blocked()
        assert breaker.reset() == "closed"
        await anyio.wait_all_tasks_blocked()
        breaker.close()  # ends both watchers; the task group exits
    expected = ["closed", "tripped_auto", "half_open", "closed", "tripped_manual", "half_open"]
    assert first == [*expected, "closed"]
    assert second == first


async def test_a_late_watcher_starts_from_the_current_state() -> None:
    breaker = CircuitBreaker(clock=FakeClock())
    breaker.disable()
    breaker.close()
    seen = [state async for state in breaker.watch()]
    assert seen == ["tripped_manual"]
