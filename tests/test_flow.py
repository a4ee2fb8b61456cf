"""The flow layer, exactly: FrameQueue + Subscription (rate cap, dispatch,
overflow, trailing delivery, decoding on pull), Outbox, PendingRequests and
Watchable.

Time is a fake clock the tests advance by hand; nothing here asserts on the
wall clock. Tasks are synchronised with ``anyio.wait_all_tasks_blocked``,
never with sleeps."""

from __future__ import annotations

import copy
import dataclasses
import itertools
import logging
import math
import pickle

import anyio
import anyio.lowlevel
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from _util import examples
from ros_mobile_bridge import DecodeError, Message, NotConnected, ServiceError
from ros_mobile_bridge.flow import (
    FrameQueue,
    Outbox,
    PendingRequests,
    RawFrame,
    Subscription,
    Watchable,
)

# Marked here as well as by conftest: the anyio plugin must see the marker at
# collection time for parametrized async tests (conftest adds it only after
# parametrization, which leaves them without their parameters).


LOGGER = logging.getLogger("tests.test_flow")


# -- helpers ------------------------------------------------------------------
class FakeClock:
    """Monotonic seconds that move only when the test says so."""

    def __init__(self, start: float = 0.0) -> None:
        self.now = start

    def __call__(self) -> float:
        return self.now

    def set(self, now: float) -> None:
        assert now >= self.now, "a monotonic clock never goes back"
        self.now = now


class CountingDecoder:
    """Decodes the ASCII integer payload and records every call."""

    def __init__(self) -> None:
        self.calls: list[int] = []

    def __call__(self, view: memoryview) -> int:
        value = int(bytes(view))
        self.calls.append(value)
        return value


def frame(i: int, decode: object = None, *, topic: str = "/t") -> RawFrame:
    return RawFrame(
        topic=topic,
        schema_name="std_msgs/msg/Int32",
        encoding="cdr",
        payload=memoryview(str(i).encode()),
        log_time_ns=None,
        receive_time_ns=i,
        decode=decode,  # type: ignore[arg-type]
    )


def payload_id(f: RawFrame | None) -> int | None:
    return None if f is None else int(bytes(f.payload))


def take_all(q: FrameQueue) -> list[int]:
    out: list[int] = []
    while (f := q.take()) is not None:
        out.append(int(bytes(f.payload)))
    return out


def accounted(q: FrameQueue) -> int:
    """delivered + every drop + still queued (held included)."""
    return q.delivered + q.dropped_throttle + q.dropped_conflated + q.dropped_overflow + len(q)


async def pull_ready(sub: Subscription) -> list[object]:
    """Consume every message that is ready now, through ``__anext__``, and
    stop (by cancelling the consumer while it waits) once none is."""
    got: list[object] = []

    async def consume() -> None:
        async for msg in sub:
            got.append(msg.data)

    async with anyio.create_task_group() as tg:
        tg.start_soon(consume)
        await anyio.wait_all_tasks_blocked()
        tg.cancel_scope.cancel()
    return got


async def drain(sub: Subscription) -> list[object]:
    """Consume until the (closed) subscription ends."""
    return [msg.data async for msg in sub]


# -- FrameQueue: no cap ---------------------------------------------------------
def test_without_a_cap_every_frame_passes_in_order() -> None:
    clock = FakeClock()
    q = FrameQueue(buffer=1000, clock=clock)
    for i in range(500):
        q.offer(frame(i))  # all at the same instant: no cap, nothing held
    assert len(q) == 500
    assert take_all(q) == list(range(500))
    assert q.take() is None
    assert q.received == 500
    assert q.dropped_throttle == q.dropped_conflated == q.dropped_overflow == 0
    assert q.interval == 0.0


# -- FrameQueue: the max_hz cap ---------------------------------------------------
async def test_max_hz_10_on_1ms_frames_delivers_11_and_decodes_only_those() -> None:
    # 1000 frames at t = 0, 1, ..., 999 ms under max_hz=10 (windows of 100 ms).
    # What the algorithm promises:
    #   * frame 0 opens the first window and is delivered at once            (1)
    #   * each later window start (100, 200, ..., 900 ms) releases the newest
    #     frame held during the window before it                            (9)
    #   * the newest frame of the last window (999) is held and released
    #     once that window ends, at 1000 ms                                   (1)
    # so 11 delivered (10 of them within the simulated second) and the other
    # 989 superseded while held: dropped_throttle, never decoded.
    clock = FakeClock()
    decoder = CountingDecoder()
    q = FrameQueue(max_hz=10, buffer=64, clock=clock)
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(1000):
        clock.set(i / 1000)
        q.offer(frame(i, decoder))
    assert q.received == 1000
    assert q.dropped_throttle == 989
    assert len(q) == 11  # 10 ready + 1 held
    assert decoder.calls == []  # offering never decodes

    # Within the second: exactly 10 are ready, the 11th is still held.
    ready = await pull_ready(sub)
    assert len(ready) == 10
    assert len(q) == 1
    assert q.take() is None  # the last window has not ended yet

    clock.set(1.001)  # the last window has ended (1 ms of float slack)
    (last,) = await pull_ready(sub)
    assert last == 999
    delivered = [*ready, last]
    assert q.delivered == 11
    assert q.dropped_throttle == 989
    assert accounted(q) == q.received == 1000

    # Only delivered frames were decoded, each once, in delivery order.
    assert decoder.calls == delivered
    assert delivered[0] == 0
    # The k-th release is the newest frame before the k*100 ms boundary
    # (frame 100k-1), or frame 100k where float rounding of the accumulated
    # window start puts that frame just before the boundary.
    for k in range(1, 10):
        assert delivered[k] in (100 * k - 1, 100 * k), (k, delivered)
    assert sub.stats.effective_interval_ms == pytest.approx(100.0)

    q.close()
    with pytest.raises(StopAsyncIteration):
        await sub.__anext__()


def test_max_hz_exact_schedule_with_dyadic_times() -> None:
    # Exactly representable times (1/1024 s steps, max_hz=8 -> 0.125 s
    # windows), so the schedule is exact to the frame.
    clock = FakeClock()
    q = FrameQueue(max_hz=8, buffer=64, clock=clock)
    out: list[int] = []
    for i in range(1024):
        clock.set(i / 1024)
        q.offer(frame(i))
        out += take_all(q)
    assert out == [0, *(128 * k - 1 for k in range(1, 8))]
    clock.set(1023 / 1024 + 1 / 2048)
    assert q.take() is None  # the last window (0.875 .. 1.0) is still open
    clock.set(1.0)
    assert payload_id(q.take()) == 1023
    assert q.take() is None
    assert q.received == 1024
    assert q.dropped_throttle == 1024 - 9


def test_a_frame_after_a_quiet_gap_is_delivered_at_once() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=4, clock=clock)  # 0.25 s windows
    q.offer(frame(0))
    clock.set(0.25)
    q.offer(frame(1))  # exactly one interval later: a new window
    clock.set(10.0)
    q.offer(frame(2))
    assert take_all(q) == [0, 1, 2]
    assert q.dropped_throttle == 0


def test_trailing_delivery_releases_the_newest_frame_of_a_burst_when_the_window_ends() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=4, clock=clock)  # 0.25 s windows, dyadic times below
    q.offer(frame(0))  # t=0: delivered at once, opens the window
    for i, t in [(1, 0.0625), (2, 0.125), (3, 0.1875)]:
        clock.set(t)
        q.offer(frame(i))  # burst inside the window: held, superseded
    # then silence
    assert take_all(q) == [0]
    assert q.take() is None
    clock.set(0.25 - 1 / 1024)
    assert q.take() is None  # not before the window ends
    clock.set(0.25)
    assert payload_id(q.take()) == 3  # the last message before quiet arrives
    assert q.take() is None
    clock.set(100.0)
    assert q.take() is None  # released once, not again
    assert q.dropped_throttle == 2
    assert q.received == 4


def test_the_adaptive_interval_is_read_once_per_window_not_per_frame() -> None:
    clock = FakeClock()
    reads: list[float] = []
    adaptive = 0.0

    def interval() -> float:
        reads.append(clock.now)
        return adaptive

    q = FrameQueue(max_hz=4, adaptive=interval, clock=clock)  # 0.25 s windows
    for i in range(16):  # 64 Hz for 0.25 s: the first delivered, 15 replace each other
        clock.set(i / 64)
        q.offer(frame(i))
    assert reads == [0.0, 1 / 64]  # opening the window, then holding the first replaced
    adaptive = 1.0  # the throttle tightened: read when the window ends
    clock.set(0.25)
    q.offer(frame(16))
    assert reads[-1] == 0.25
    assert q.interval == 1.0
    assert take_all(q) == [0]  # the held frame's window is now 1 s
    clock.set(0.5)
    q.offer(frame(17))  # inside the longer window: replaced, no read
    assert len(reads) == 3
    clock.set(1.0)
    assert take_all(q) == [17]
    assert (q.received, q.dropped_throttle, len(q)) == (18, 16, 0)


async def test_a_consumer_waiting_on_a_held_frame_gets_it_when_the_window_ends() -> None:
    # The consumer waits in get() while the rate cap holds the newest frame;
    # once the (fake) window has ended the frame is delivered without any new
    # frame arriving. max_hz=100 bounds get()'s internal re-check to 10 ms.
    clock = FakeClock()
    q = FrameQueue(max_hz=100, clock=clock)
    sub = Subscription("/t", q, logger=LOGGER)
    q.offer(frame(0, CountingDecoder()))
    clock.set(0.001)
    q.offer(frame(1, CountingDecoder()))  # held
    assert (await sub.__anext__()).data == 0
    got: list[object] = []

    async def consume() -> None:
        got.append((await sub.__anext__()).data)

    with anyio.fail_after(10):
        async with anyio.create_task_group() as tg:
            tg.start_soon(consume)
            await anyio.wait_all_tasks_blocked()
            assert got == []  # still held: the window has not ended
            clock.set(0.01)
    assert got == [1]
    assert q.dropped_throttle == 0


# -- FrameQueue: dispatch and overflow ---------------------------------------------
async def test_dispatch_latest_keeps_only_the_newest_frame() -> None:
    decoder = CountingDecoder()
    q = FrameQueue(dispatch="latest", buffer=64, clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(10):
        q.offer(frame(i, decoder))
    assert len(q) == 1
    assert q.dropped_conflated == 9
    assert q.dropped_overflow == 0
    assert await pull_ready(sub) == [9]
    assert decoder.calls == [9]
    assert accounted(q) == q.received == 10


def test_dispatch_latest_with_a_cap_conflates_the_released_frame() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=4, dispatch="latest", clock=clock)
    q.offer(frame(0))
    clock.set(0.125)
    q.offer(frame(1))  # held
    clock.set(0.25)  # the window ends: 1 is released and supersedes 0
    assert payload_id(q.take()) == 1
    assert q.dropped_conflated == 1
    assert q.dropped_throttle == 0


async def test_dispatch_all_with_a_full_buffer_drops_the_oldest_undecoded() -> None:
    decoder = CountingDecoder()
    q = FrameQueue(dispatch="all", buffer=3, clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(10):
        q.offer(frame(i, decoder))
    assert q.dropped_overflow == 7
    assert q.dropped_conflated == 0
    assert len(q) == 3
    assert await pull_ready(sub) == [7, 8, 9]
    assert decoder.calls == [7, 8, 9]
    stats = sub.stats
    assert (stats.received, stats.delivered, stats.dropped_overflow) == (10, 3, 7)


# -- FrameQueue: the accounting invariant --------------------------------------------
_ARRIVALS = st.lists(
    st.one_of(
        st.tuples(st.just("frame"), st.integers(0, 400)),  # ms since the previous event
        st.tuples(st.just("tick"), st.integers(0, 400)),  # time passes, nothing arrives
        st.tuples(st.just("pull"), st.just(0)),  # consume whatever is ready
    ),
    max_size=80,
)


async def _run_arrivals(
    ops: list[tuple[str, int]], max_hz: float | None, dispatch: str, buffer: int
) -> None:
    clock = FakeClock()
    decoder = CountingDecoder()
    q = FrameQueue(max_hz=max_hz, dispatch=dispatch, buffer=buffer, clock=clock)  # type: ignore[arg-type]
    sub = Subscription("/t", q, logger=LOGGER)
    delivered: list[object] = []
    offered = 0

    def check() -> None:
        s = sub.stats
        assert s.received == offered
        assert s.received == (
            s.delivered + s.dropped_throttle + s.dropped_conflated + s.dropped_overflow + len(q)
        )
        assert s.delivered == len(delivered) == len(decoder.calls)
        assert len(q) <= q.buffer + (1 if max_hz else 0)
        if dispatch == "latest":
            assert s.dropped_overflow == 0
        else:
            assert s.dropped_conflated == 0
        if not max_hz:
            assert s.dropped_throttle == 0

    for kind, ms in ops:
        if kind == "frame":
            clock.set(clock.now + ms / 1000)
            q.offer(frame(offered, decoder))
            offered += 1
        elif kind == "tick":
            clock.set(clock.now + ms / 1000)
        else:
            delivered += await pull_ready(sub)
        check()
    sub.close()
    delivered += await drain(sub)
    check()
    assert len(q) == 0
    # Order is kept, only delivered frames were decoded, and the last frame
    # before the end always arrives.
    assert delivered == sorted(set(delivered))  # type: ignore[type-var]
    assert decoder.calls == delivered
    if offered:
        assert delivered[-1] == offered - 1


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
@settings(deadline=None, max_examples=examples(60))
@given(
    ops=_ARRIVALS,
    max_hz=st.sampled_from([None, 1, 4, 10, 30, 1000, 2.5]),
    dispatch=st.sampled_from(["all", "latest"]),
    buffer=st.integers(1, 6),
)
def test_every_received_frame_is_delivered_dropped_or_queued(
    backend: str,
    ops: list[tuple[str, int]],
    max_hz: float | None,
    dispatch: str,
    buffer: int,
) -> None:
    anyio.run(_run_arrivals, ops, max_hz, dispatch, buffer, backend=backend)


# -- FrameQueue: close -----------------------------------------------------------------
async def test_close_drains_queued_then_the_held_frame_then_ends() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=4, clock=clock)
    q.offer(frame(0))
    clock.set(0.1)
    q.offer(frame(1))  # held
    clock.set(0.2)
    q.offer(frame(2))  # held, 1 dropped
    q.close()
    assert q.closed
    assert payload_id(await q.get()) == 0
    assert payload_id(await q.get()) == 2  # held, delivered although its window is open
    with pytest.raises(anyio.EndOfStream):
        await q.get()
    with pytest.raises(anyio.EndOfStream):
        await q.get()  # and stays ended
    assert q.dropped_throttle == 1


async def test_close_wakes_a_waiting_consumer() -> None:
    q = FrameQueue(clock=FakeClock())
    ended = False

    async def consume() -> None:
        nonlocal ended
        with pytest.raises(anyio.EndOfStream):
            await q.get()
        ended = True

    async with anyio.create_task_group() as tg:
        tg.start_soon(consume)
        await anyio.wait_all_tasks_blocked()
        assert not ended
        q.close()
    assert ended


def test_a_frame_offered_after_close_keeps_the_counters_consistent() -> None:
    q = FrameQueue(clock=FakeClock())
    q.offer(frame(0))
    q.close()
    q.offer(frame(1))
    assert accounted(q) == q.received


# -- Subscription ---------------------------------------------------------------------
async def test_iteration_ends_after_close_once_queued_messages_are_consumed() -> None:
    decoder = CountingDecoder()
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(3):
        q.offer(frame(i, decoder))
    sub.close()
    sub.close()  # idempotent
    assert await drain(sub) == [0, 1, 2]
    with pytest.raises(StopAsyncIteration):
        await sub.__anext__()


async def test_close_ends_a_waiting_iteration() -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    got: list[object] = []

    async def consume() -> None:
        got.extend(await drain(sub))

    async with anyio.create_task_group() as tg:
        tg.start_soon(consume)
        await anyio.wait_all_tasks_blocked()
        q.offer(frame(7, CountingDecoder()))
        await anyio.wait_all_tasks_blocked()
        assert got == []  # still iterating
        sub.close()
    assert got == [7]


async def test_fail_raises_the_error_after_the_queued_messages() -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    q.offer(frame(1, CountingDecoder()))
    error = NotConnected("connection lost")
    q.fail(error)  # the router fails the queue when the connection is gone
    assert (await sub.__anext__()).data == 1
    with pytest.raises(NotConnected) as info:
        await sub.__anext__()
    assert info.value is error
    with pytest.raises(NotConnected):
        async for _ in sub:
            pass


async def test_fail_wakes_a_waiting_iteration_with_the_error() -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    raised: list[BaseException] = []

    async def consume() -> None:
        try:
            await sub.__anext__()
        except NotConnected as exc:
            raised.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(consume)
        await anyio.wait_all_tasks_blocked()
        q.fail(NotConnected("gone"))
    assert len(raised) == 1


async def test_wait_active_returns_on_activation_and_raises_once_closed() -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    assert sub.state == "pending"
    done = False

    async def wait() -> None:
        nonlocal done
        await sub.wait_active()
        done = True

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait)
        await anyio.wait_all_tasks_blocked()
        assert not done
        q.set_state("active")  # as the router does
    assert done
    assert sub.state == "active"
    await sub.wait_active()  # already active: returns at once

    other = Subscription("/u", FrameQueue(clock=FakeClock()), logger=LOGGER)
    other.close()
    with pytest.raises(NotConnected, match="closed"):
        await other.wait_active()


async def test_message_fields_come_from_the_frame() -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    q.offer(
        RawFrame(
            topic="/t",
            schema_name="pkg/msg/T",
            encoding="json",
            payload=memoryview(b"42"),
            log_time_ns=5,
            receive_time_ns=6,
            decode=lambda view: {"v": int(bytes(view))},
        )
    )
    msg = await sub.__anext__()
    assert (msg.topic, msg.schema_name, msg.encoding) == ("/t", "pkg/msg/T", "json")
    assert (msg.data, msg.log_time_ns, msg.receive_time_ns, msg.byte_size) == ({"v": 42}, 5, 6, 2)
    assert msg.decode_error is None


def _raise_decode_error(view: memoryview) -> object:
    raise DecodeError("truncated CDR")


def _raise_value_error(view: memoryview) -> object:
    raise ValueError("codec bug")


@pytest.mark.parametrize(
    ("decode", "expected_error"),
    [
        (_raise_decode_error, "truncated CDR"),
        (_raise_value_error, "ValueError: codec bug"),
        (None, "no decoder"),
    ],
)
async def test_a_payload_that_does_not_decode_is_delivered_raw(
    decode: object, expected_error: str, caplog: pytest.LogCaptureFixture
) -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    q.offer(frame(123, decode))
    q.offer(frame(4, CountingDecoder()))
    with caplog.at_level(logging.WARNING, logger=LOGGER.name):
        bad = await sub.__anext__()
    assert isinstance(bad.data, memoryview)
    assert bytes(bad.data) == b"123"
    assert bad.decode_error is not None
    assert expected_error in bad.decode_error
    assert bad.byte_size == 3
    assert any("delivering it raw" in r.getMessage() for r in caplog.records)
    good = await sub.__anext__()  # the subscription carries on
    assert good.data == 4
    assert good.decode_error is None
    stats = sub.stats
    assert (stats.delivered, stats.decode_failures) == (2, 1)


async def test_a_cancelled_next_does_not_lose_a_waiting_frame() -> None:
    decoder = CountingDecoder()
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    q.offer(frame(1, decoder))
    with anyio.CancelScope() as scope:
        scope.cancel()
        await sub.__anext__()
    assert accounted(q) == q.received
    assert (await sub.__anext__()).data == 1


async def test_a_cancelled_consumer_of_a_steady_stream_stops_within_32_messages() -> None:
    """The cancellation check runs on the first call after a wait and at the
    yield every 32nd while frames wait; whatever was taken before it is
    delivered, none is lost."""
    decoder = CountingDecoder()
    q = FrameQueue(clock=FakeClock(), buffer=100)
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(80):
        q.offer(frame(i, decoder))
    got: list[object] = []
    with anyio.CancelScope() as scope:
        got.append((await sub.__anext__()).data)
        scope.cancel()
        while True:
            got.append((await sub.__anext__()).data)
    assert scope.cancelled_caught
    assert 1 <= len(got) <= 32
    assert got == list(range(len(got)))
    assert accounted(q) == q.received
    assert (await sub.__anext__()).data == len(got)  # the rest still waits, in order


async def messages_between_yields(
    monkeypatch: pytest.MonkeyPatch, payload_size: int, count: int
) -> list[int]:
    """Drain ``count`` queued frames of ``payload_size`` bytes with ``async
    for``: how many messages the consumer delivered between two turns it
    gave the loop (its ``anyio.lowlevel.checkpoint`` calls)."""
    payload = memoryview(bytes(payload_size))
    q = FrameQueue(clock=FakeClock(), buffer=count, max_bytes=1 << 40)
    sub = Subscription("/t", q, logger=LOGGER)
    for i in range(count):
        q.offer(RawFrame("/t", "sensor_msgs/msg/Image", "cdr", payload, None, i, lambda v: None))
    q.close()
    yields: list[int] = []
    checkpoint = anyio.lowlevel.checkpoint

    async def counted_checkpoint() -> None:
        yields.append(q.delivered)
        await checkpoint()

    monkeypatch.setattr(anyio.lowlevel, "checkpoint", counted_checkpoint)
    got = [message async for message in sub]
    assert len(got) == count
    marks = [0, *yields, count]
    return [b - a for a, b in itertools.pairwise(marks)]


async def test_the_consumer_yields_every_32_small_messages(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the first call counts as the first of 32, and so does the message
    # taken at a yield (the yield took a pending cancellation)
    assert await messages_between_yields(monkeypatch, 100, 200) == [32] * 6 + [8]


async def test_the_consumer_yields_after_about_4_mib_of_images(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A 921,652-byte image counts as 8 messages: 4 images between two
    turns of the loop, not 1 (the reader then ran ahead with one fresh image
    buffer per turn) nor 32 (120 MB decoded without a turn)."""
    assert await messages_between_yields(monkeypatch, 921_652, 20) == [4] * 5 + [0]


async def test_a_drain_of_waiting_messages_checks_for_cancellation_at_its_yields_only(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    # the first call checks alone; after that every check is a yield's (none
    # right after one)
    q = FrameQueue(clock=FakeClock(), buffer=200)
    sub = Subscription("/t", q, logger=LOGGER)
    decoder = CountingDecoder()
    for i in range(200):
        q.offer(frame(i, decoder))
    q.close()
    checks: list[int] = []
    check = anyio.lowlevel.checkpoint_if_cancelled

    async def counted_check() -> None:
        checks.append(q.delivered)
        await check()

    monkeypatch.setattr(anyio.lowlevel, "checkpoint_if_cancelled", counted_check)
    assert [m.data async for m in sub] == list(range(200))
    assert checks == [0]


def mixed_frames(q: FrameQueue) -> None:
    """Good frames 0..9, with 3 undecodable and 6 without a decoder."""
    for i in range(10):
        decode: object = CountingDecoder()
        if i == 3:
            decode = _raise_value_error
        elif i == 6:
            decode = None
        q.offer(frame(i, decode))


@pytest.mark.parametrize("form", ["async for", "batches"])
async def test_both_forms_deliver_the_same_messages_and_count_them(form: str) -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER)
    mixed_frames(q)
    q.close()
    if form == "async for":
        got = [m async for m in sub]
    else:
        batches = [b async for b in sub.batches(max_size=4)]
        assert [len(b) for b in batches] == [4, 4, 2]
        got = [m for b in batches for m in b]
    assert [bytes(m.data) if m.decode_error else m.data for m in got] == [
        0, 1, 2, b"3", 4, 5, b"6", 7, 8, 9,
    ]  # fmt: skip
    assert [m.receive_time_ns for m in got] == list(range(10))
    assert [m.byte_size for m in got] == [1] * 10
    assert all(type(m) is Message and m.topic == "/t" for m in got)
    assert ["codec bug" in (m.decode_error or "") for m in got].count(True) == 1
    stats = sub.stats
    assert (stats.delivered, stats.decode_failures) == (10, 2)


@pytest.mark.parametrize("form", ["async for", "batches"])
async def test_a_raw_subscription_delivers_payloads_in_both_forms(form: str) -> None:
    q = FrameQueue(clock=FakeClock())
    sub = Subscription("/t", q, logger=LOGGER, decode=False)
    mixed_frames(q)
    q.close()
    if form == "async for":
        got = [m async for m in sub]
    else:
        got = [m async for b in sub.batches(max_size=3) for m in b]
    assert [bytes(m.data) for m in got] == [str(i).encode() for i in range(10)]
    assert all(m.decode_error is None for m in got)
    stats = sub.stats
    assert (stats.delivered, stats.decode_failures) == (10, 0)


# -- FrameQueue: argument validation ------------------------------------------------------
@pytest.mark.parametrize("max_hz", [0, 0.0, -1, -0.5, math.nan])
def test_max_hz_must_be_positive(max_hz: float) -> None:
    with pytest.raises(ValueError, match="max_hz"):
        FrameQueue(max_hz=max_hz)


@pytest.mark.parametrize("max_hz", [True, False, "10", b"10", [10]])
def test_max_hz_must_be_a_number(max_hz: object) -> None:
    with pytest.raises(TypeError, match="max_hz"):
        FrameQueue(max_hz=max_hz)  # type: ignore[arg-type]


@pytest.mark.parametrize("dispatch", ["newest", "ALL", "", None, 1])
def test_dispatch_must_be_all_or_latest(dispatch: object) -> None:
    with pytest.raises(ValueError, match="dispatch"):
        FrameQueue(dispatch=dispatch)  # type: ignore[arg-type]


@pytest.mark.parametrize("buffer", [0, -1])
def test_buffer_must_be_at_least_one(buffer: int) -> None:
    with pytest.raises(ValueError, match="buffer"):
        FrameQueue(buffer=buffer)


@pytest.mark.parametrize("buffer", [True, False, 1.0, "4", None])
def test_buffer_must_be_an_int(buffer: object) -> None:
    with pytest.raises(TypeError, match="buffer"):
        FrameQueue(buffer=buffer)  # type: ignore[arg-type]


def test_valid_arguments_are_kept() -> None:
    q = FrameQueue(max_hz=2.5, dispatch="all", buffer=7)
    assert (q.max_hz, q.dispatch, q.buffer, q.interval) == (2.5, "all", 7, 0.4)
    latest = FrameQueue(max_hz=None, dispatch="latest", buffer=7)
    assert (latest.buffer, latest.interval) == (1, 0.0)


# -- Outbox -------------------------------------------------------------------------------
async def test_control_frames_leave_before_data_frames() -> None:
    box = Outbox()
    await box.put_data("/map", "d1")
    await box.put_data("/image", b"d2")
    box.put_control("/cmd_vel", "stop")
    assert box.has_control
    assert len(box) == 3
    assert [box.pop(), box.pop(), box.pop(), box.pop()] == ["stop", "d1", b"d2", None]
    assert not box.has_control
    assert len(box) == 0


async def test_control_frames_for_one_key_coalesce_to_the_newest() -> None:
    box = Outbox()
    for i in range(10):
        box.put_control("/cmd_vel", f"v{i}")
    assert len(box) == 1
    assert box.coalesced == 9
    assert box.pop() == "v9"
    assert box.pop() is None


async def test_a_re_put_control_key_takes_the_newest_place() -> None:
    box = Outbox()
    box.put_control("a", "a1")
    box.put_control("b", "b1")
    box.put_control("a", "a2")
    assert box.pop_control() == "b1"
    assert box.pop_control() == "a2"
    assert box.pop_control() is None
    assert box.coalesced == 1


async def test_a_control_frame_drops_older_data_frames_for_its_key() -> None:
    box = Outbox()
    await box.put_data("/cmd_vel", "old1")
    await box.put_data("/odom", "other")
    await box.put_data("/cmd_vel", "old2")
    box.put_control("/cmd_vel", "stop")
    await box.put_data("/cmd_vel", "newer")  # after the control frame: kept
    assert box.coalesced == 2
    assert [box.pop(), box.pop(), box.pop(), box.pop()] == ["stop", "other", "newer", None]


async def test_data_frames_are_fifo() -> None:
    box = Outbox()
    for i in range(20):
        await box.put_data(i % 3, f"m{i}")
    assert [box.pop() for _ in range(20)] == [f"m{i}" for i in range(20)]
    assert box.pop() is None


async def test_put_data_waits_while_full_and_resumes_after_pop() -> None:
    box = Outbox(data_limit=2)
    await box.put_data("k", "a")
    await box.put_data("k", "b")
    done: list[str] = []

    async def put(message: str) -> None:
        await box.put_data("k", message)
        done.append(message)

    async with anyio.create_task_group() as tg:
        tg.start_soon(put, "c")
        await anyio.wait_all_tasks_blocked()
        assert done == []
        assert len(box) == 2
        box.put_control("other", "ctl")  # control frames never wait
        assert box.pop() == "ctl"  # popping control makes no data room
        await anyio.wait_all_tasks_blocked()
        assert done == []
        assert box.pop() == "a"
        await anyio.wait_all_tasks_blocked()
        assert done == ["c"]
        tg.start_soon(put, "d")
        await anyio.wait_all_tasks_blocked()
        assert done == ["c"]  # full again
        assert box.drop_data() == 2  # drop_data makes room too
    assert done == ["c", "d"]
    assert [box.pop(), box.pop()] == ["d", None]


async def test_several_blocked_publishers_each_get_in_in_turn() -> None:
    box = Outbox(data_limit=1)
    await box.put_data("k", "first")
    done: list[str] = []

    async def put(message: str) -> None:
        await box.put_data("k", message)
        done.append(message)

    async with anyio.create_task_group() as tg:
        for name in ("x", "y"):
            tg.start_soon(put, name)
        await anyio.wait_all_tasks_blocked()
        sent = [box.pop()]
        while len(sent) < 3:
            await anyio.wait_all_tasks_blocked()
            sent.append(box.pop())
    assert sent[0] == "first"
    assert sorted(sent[1:]) == ["x", "y"]
    assert sorted(done) == ["x", "y"]


async def test_get_waits_for_a_frame() -> None:
    box = Outbox()
    got: list[object] = []

    async def writer() -> None:
        got.append(await box.get())
        got.append(await box.get())

    async with anyio.create_task_group() as tg:
        tg.start_soon(writer)
        await anyio.wait_all_tasks_blocked()
        assert got == []
        box.put_control("/cmd_vel", "stop")
        await anyio.wait_all_tasks_blocked()
        assert got == ["stop"]
        await box.put_data("/x", b"data")
    assert got == ["stop", b"data"]
    await box.put_data("/x", "ready")
    assert await box.get() == "ready"  # no wait when a frame is queued


def test_outbox_data_limit_must_be_positive() -> None:
    with pytest.raises(ValueError, match="data_limit"):
        Outbox(data_limit=0)


# -- PendingRequests ------------------------------------------------------------------------
async def test_resolve_answers_the_waiter() -> None:
    pending: PendingRequests[str] = PendingRequests()
    pending.register(1)
    assert 1 in pending
    got: list[str] = []

    async def wait() -> None:
        got.append(await pending.wait(1))

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait)
        await anyio.wait_all_tasks_blocked()
        assert got == []
        assert pending.resolve(1, "answer")
    assert got == ["answer"]
    assert 1 not in pending
    assert len(pending) == 0


async def test_an_answer_before_wait_is_kept() -> None:
    pending: PendingRequests[int] = PendingRequests()
    pending.register("id")
    assert pending.resolve("id", 5)
    assert not pending.resolve("id", 6)  # the first answer wins
    assert not pending.fail("id", NotConnected())
    assert await pending.wait("id") == 5


async def test_fail_raises_in_the_waiter() -> None:
    pending: PendingRequests[int] = PendingRequests()
    pending.register(7)
    error = ServiceError("/srv", "nope")
    assert pending.fail(7, error)
    with pytest.raises(ServiceError) as info:
        await pending.wait(7)
    assert info.value is error
    assert 7 not in pending


async def test_fail_all_fails_every_waiter() -> None:
    pending: PendingRequests[int] = PendingRequests()
    for key in range(3):
        pending.register(key)
    pending.resolve(0, 0)  # already answered: not failed
    raised: list[BaseException] = []

    async def wait(key: int) -> None:
        try:
            await pending.wait(key)
        except NotConnected as exc:
            raised.append(exc)

    async with anyio.create_task_group() as tg:
        tg.start_soon(wait, 1)
        tg.start_soon(wait, 2)
        await anyio.wait_all_tasks_blocked()
        assert pending.fail_all(NotConnected("lost")) == 2
        assert pending.fail_all(NotConnected("again")) == 0
    assert len(raised) == 2
    assert all(str(exc) == "lost" for exc in raised)
    assert await pending.wait(0) == 0
    assert len(pending) == 0


async def test_discard_forgets_a_request() -> None:
    pending: PendingRequests[int] = PendingRequests()
    pending.register("x")
    pending.discard("x")
    pending.discard("x")  # unknown keys are fine
    assert "x" not in pending
    assert not pending.resolve("x", 1)
    assert not pending.fail("x", NotConnected())
    pending.register("x")  # the key can be reused


async def test_late_answers_are_ignored() -> None:
    pending: PendingRequests[int] = PendingRequests()
    assert not pending.resolve("never", 1)
    assert not pending.fail("never", NotConnected())
    pending.register(1)
    pending.resolve(1, 10)
    assert await pending.wait(1) == 10
    assert not pending.resolve(1, 11)
    assert not pending.fail(1, NotConnected())
    assert len(pending) == 0


async def test_a_cancelled_wait_removes_the_registration() -> None:
    pending: PendingRequests[int] = PendingRequests()
    pending.register(1)
    async with anyio.create_task_group() as tg:
        tg.start_soon(pending.wait, 1)
        await anyio.wait_all_tasks_blocked()
        assert 1 in pending
        tg.cancel_scope.cancel()
    assert 1 not in pending
    assert not pending.resolve(1, 5)  # the late answer is ignored
    pending.register(2)
    with anyio.CancelScope() as scope:
        scope.cancel()
        await pending.wait(2)
    assert scope.cancelled_caught
    assert len(pending) == 0


async def test_registering_a_pending_key_twice_raises() -> None:
    pending: PendingRequests[int] = PendingRequests()
    pending.register(1)
    with pytest.raises(ValueError, match="already pending"):
        pending.register(1)
    pending.resolve(1, 1)
    assert await pending.wait(1) == 1
    pending.register(1)  # answered and collected: free again


# -- Watchable ----------------------------------------------------------------------------------
async def test_a_watcher_gets_the_current_value_at_once_then_changes() -> None:
    value = Watchable("connecting")
    watcher = value.watch()
    assert await watcher.__anext__() == "connecting"
    got: list[str] = []

    async def watch() -> None:
        async for v in watcher:
            got.append(v)

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch)
        await anyio.wait_all_tasks_blocked()
        assert got == []
        assert value.set("connected")
        await anyio.wait_all_tasks_blocked()
        assert got == ["connected"]
        value.set("closed")
        await anyio.wait_all_tasks_blocked()
        value.close()
    assert got == ["connected", "closed"]
    assert value.value == "closed"


async def test_a_slow_watcher_sees_only_the_newest_value() -> None:
    value = Watchable(0)
    watcher = value.watch()
    assert await watcher.__anext__() == 0
    for i in range(1, 6):
        assert value.set(i)
    assert await watcher.__anext__() == 5
    late = value.watch()
    assert await late.__anext__() == 5  # a new watcher starts at the current value


async def test_close_ends_iteration() -> None:
    value = Watchable([1])
    watcher = value.watch()
    ended = False

    async def watch() -> None:
        nonlocal ended
        async for _ in watcher:
            pass
        ended = True

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch)
        await anyio.wait_all_tasks_blocked()
        assert not ended
        value.close()
    assert ended
    with pytest.raises(StopAsyncIteration):
        await watcher.__anext__()


async def test_setting_an_equal_value_does_not_wake_watchers() -> None:
    value = Watchable(["/a", "/b"])
    got: list[list[str]] = []

    async def watch() -> None:
        async for v in value.watch():
            got.append(v)

    async with anyio.create_task_group() as tg:
        tg.start_soon(watch)
        await anyio.wait_all_tasks_blocked()
        assert got == [["/a", "/b"]]
        assert not value.set(["/a", "/b"])  # equal, though another object
        await anyio.wait_all_tasks_blocked()
        assert got == [["/a", "/b"]]
        assert value.set(["/a"])
        await anyio.wait_all_tasks_blocked()
        assert got == [["/a", "/b"], ["/a"]]
        value.close()


# -- FrameQueue: the byte bound ---------------------------------------------------------
def test_queue_is_bounded_by_bytes_and_keeps_the_newest() -> None:
    q = FrameQueue(buffer=1000, max_bytes=10)
    for i in range(100, 110):  # 3-byte payloads: at most 3 fit in 10 bytes
        q.offer(frame(i))
    assert [payload_id(q.take()) for _ in range(3)] == [107, 108, 109]
    assert q.take() is None
    assert q.dropped_overflow == 7
    assert q.received == 10


def test_a_frame_larger_than_the_byte_bound_is_still_delivered() -> None:
    q = FrameQueue(max_bytes=2)
    q.offer(frame(1000))  # 4 bytes, alone in the queue
    assert payload_id(q.take()) == 1000


@pytest.mark.parametrize("max_bytes", [0, -1, True, 1.5])
def test_max_bytes_must_be_a_positive_int(max_bytes: object) -> None:
    with pytest.raises(ValueError, match="max_bytes"):
        FrameQueue(max_bytes=max_bytes)  # type: ignore[arg-type]


# -- PendingRequests.request ------------------------------------------------------------
async def test_request_sends_then_waits_and_a_failed_send_leaves_nothing_pending() -> None:
    pending: PendingRequests[str] = PendingRequests()
    sent: list[int] = []

    async def send() -> None:
        sent.append(1)
        pending.resolve(1, "answer")  # answered as soon as it is on the wire

    assert await pending.request(1, send) == "answer"
    assert sent == [1]
    assert len(pending) == 0

    async def broken() -> None:
        raise NotConnected("socket gone")

    with pytest.raises(NotConnected, match="socket gone"):
        await pending.request(2, broken)
    assert 2 not in pending
    assert len(pending) == 0


def test_the_fast_message_constructor_builds_the_same_frozen_message() -> None:
    from dataclasses import FrozenInstanceError

    from ros_mobile_bridge._types import Message, new_message

    args = ("/t", "std_msgs/msg/String", "cdr", {"data": "x"}, 5, None, 9, "why", 41)
    fast = new_message(*args)
    assert type(fast) is Message
    assert fast == Message(*args)
    assert hash(fast.topic) == hash("/t")
    with pytest.raises(FrozenInstanceError):
        fast.topic = "/other"  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(fast)) == fast
    assert copy.copy(fast) == fast
    assert dataclasses.replace(fast, topic="/u") == Message("/u", *args[1:])


def test_a_frame_becomes_the_same_frozen_message_as_message_would_build() -> None:
    from dataclasses import FrozenInstanceError

    from ros_mobile_bridge.flow._frame import frame_message

    raw = RawFrame("/t", "std_msgs/msg/String", "cdr", memoryview(b"xy"), 7, 5, None, 41)
    built = frame_message(raw, {"data": "x"}, 9, "why")
    assert type(built) is Message
    assert built == Message("/t", "std_msgs/msg/String", "cdr", {"data": "x"}, 5, 7, 9, "why", 41)
    with pytest.raises(FrozenInstanceError):
        built.topic = "/other"  # type: ignore[misc]
    assert pickle.loads(pickle.dumps(built)) == built


def test_an_unfrozen_twin_needs_a_slotted_class_deriving_from_object_alone() -> None:
    from ros_mobile_bridge._slots import unfrozen_twin

    class Plain:
        pass

    @dataclasses.dataclass(frozen=True, slots=True)
    class Base:
        a: int

    @dataclasses.dataclass(frozen=True, slots=True)
    class Derived(Base):
        b: int

    for cls in (Plain, Derived):
        with pytest.raises(TypeError, match="not a slotted class"):
            unfrozen_twin(cls)
    twin = unfrozen_twin(Base)
    built = object.__new__(twin)
    built.a = 3
    built.__class__ = Base
    assert built == Base(3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        built.a = 4  # type: ignore[misc]


async def test_values_holding_numpy_arrays_are_stored_not_compared_into_an_error() -> None:
    # decoded feedback holds numpy arrays: == is element-wise (and raises on
    # other shapes); such a value counts as a change, never crashes the setter
    import numpy as np

    value: Watchable[object] = Watchable(None)
    watcher = value.watch()
    assert await watcher.__anext__() is None
    first = {"sequence": np.array([0, 1, 1], np.int32)}
    second = {"sequence": np.array([0, 1, 1, 2], np.int32)}
    assert value.set(first)
    assert value.set(second)  # another shape: == raises inside numpy
    assert value.set({"sequence": np.array([0, 1, 1, 2], np.int32)})  # ambiguous truth
    assert not value.set(value.value)  # the same object
    got = await watcher.__anext__()
    assert isinstance(got, dict)
    assert got["sequence"].tolist() == [0, 1, 1, 2]
