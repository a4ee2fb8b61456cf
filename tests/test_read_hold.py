"""Reads held while every subscription is inside its rate cap's window
(``FrameQueue.quiet_until``, ``WebSocket.hold_reads``): the frames that arrive
meanwhile wait in the kernel and are read together when the window ends, and
the cap delivers the newest of them, as it would have. Unit tests on a fake
clock for the queue's side; against the official Foxglove SDK server on both
loops for the connection's: fewer reads than frames, every fate counted,
fresh messages, a stopping stream's last message, and nothing that needs an
answer (a parameter request, a keep-alive pong) waits for a hold to end."""

from __future__ import annotations

import statistics
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager

import anyio
import pytest
import sniffio

import ros_mobile_bridge as rmb
from _util import fast_options as options
from _util import wait_until, websocket_of
from peers.foxglove_sdk import SdkServer, string_msg
from ros_mobile_bridge.flow import FrameQueue, RawFrame

try:
    from ros_mobile_bridge._loop._trio_timers import current_timers
except ImportError:  # trio not installed: the asyncio cases still run
    current_timers = None  # type: ignore[assignment]

# -- the queue's side (fake clock) ----------------------------------------------


class FakeClock:
    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now


def frame(i: int, size: int = 0) -> RawFrame:
    return RawFrame(
        topic="/t",
        schema_name="std_msgs/msg/Int32",
        encoding="cdr",
        payload=memoryview(str(i).encode().ljust(size, b" ")),
        log_time_ns=None,
        receive_time_ns=i,
        decode=None,
    )


def ids(q: FrameQueue) -> list[int]:
    out = []
    while (f := q.take()) is not None:
        out.append(int(bytes(f.payload)))
    return out


def test_quiet_until_is_the_end_of_the_cap_window() -> None:
    clock = FakeClock()
    uncapped = FrameQueue(clock=clock)
    uncapped.offer(frame(0))
    assert uncapped.quiet_until(clock.now) == 0.0  # no cap: every frame is wanted
    q = FrameQueue(max_hz=4, clock=clock)
    assert q.quiet_until(clock.now) == 0.0  # nothing released yet
    clock.now = 10.0
    q.offer(frame(1))
    assert ids(q) == [1]
    assert q.quiet_until(10.1) == 10.25
    q.blocked = True  # the breaker tripped
    assert q.quiet_until(10.1) == 0.0
    q.blocked = False
    q.close()
    assert q.quiet_until(10.1) == 0.0


def test_quiet_until_is_shortened_by_the_byte_budget() -> None:
    from ros_mobile_bridge.flow._subscription import HOLD_BYTES

    clock = FakeClock()
    q = FrameQueue(max_hz=1, clock=clock)
    size = HOLD_BYTES // 4
    for i in range(20):  # 20 frames of a quarter of the budget each, in one second
        clock.now = i / 20
        q.offer(frame(i, size))
    clock.now = 1.0
    q.offer(frame(20, size))  # a second has passed: the arrival rate is known
    ids(q)
    until = q.quiet_until(1.0)
    rate = 20 * size  # bytes a second
    assert until == pytest.approx(1.0 + HOLD_BYTES / rate)  # 0.2 s, not the 1 s window


def test_a_large_first_frame_bounds_the_hold_at_once() -> None:
    from ros_mobile_bridge.flow._subscription import HOLD_BYTES

    clock = FakeClock()
    q = FrameQueue(max_hz=1, clock=clock)
    clock.now = 0.01
    q.offer(frame(0, HOLD_BYTES * 4))  # a camera image, before a second has passed
    assert ids(q) == [0]
    # the rate so far (over at least 50 ms) bounds the hold, not the 1 s window
    rate = HOLD_BYTES * 4 / 0.05
    assert q.quiet_until(0.01) == pytest.approx(0.01 + HOLD_BYTES / rate)


def test_frames_read_together_after_a_hold_deliver_the_newest() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=5, buffer=64, clock=clock)
    q.offer(frame(0))
    assert ids(q) == [0]
    until = q.quiet_until(clock.now)  # the reader holds its reads until then
    assert until == 0.2
    clock.now = 0.2002  # the hold ends: four frames were waiting
    for i in range(1, 5):
        q.offer(frame(i))
        clock.now += 1e-5
    assert ids(q) == [4]
    assert (q.received, q.dropped_throttle) == (5, 3)


def test_without_a_hold_the_first_frame_after_the_window_passes() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=5, buffer=64, clock=clock)
    q.offer(frame(0))
    assert ids(q) == [0]
    clock.now = 0.2002
    for i in range(1, 5):
        q.offer(frame(i))
        clock.now += 1e-5
    # the first passes at once, the rest are held for the next window
    assert ids(q) == [1]
    clock.now = 0.4
    assert ids(q) == [4]


def test_a_release_a_little_late_keeps_the_cadence() -> None:
    clock = FakeClock()
    q = FrameQueue(max_hz=5, buffer=64, clock=clock)
    q.offer(frame(0))
    clock.now = 0.21  # 10 ms after the window ended (a loaded loop)
    q.offer(frame(1))
    assert ids(q) == [0, 1]
    assert q.quiet_until(clock.now) == pytest.approx(0.4)  # not 0.41: delays do not add up
    clock.now = 0.4
    q.offer(frame(2))
    clock.now = 0.9  # far beyond: the next window starts at this release
    q.offer(frame(3))
    assert ids(q) == [2, 3]
    assert q.quiet_until(clock.now) == pytest.approx(1.1)


# -- the connection's side (the Foxglove SDK server) -------------------------------


class Ticker:
    """Logs ``/tick`` (a String holding its sequence number) at ``hz`` from a
    thread; ``sent`` is how many were logged so far."""

    def __init__(self, server: SdkServer, hz: float) -> None:
        self.channel = server.channel("/tick", "std_msgs/msg/String")
        self.hz = hz
        self.sent = 0
        self._stop = threading.Event()

    def run(self) -> None:
        start = time.monotonic()
        while not self._stop.is_set():
            self.channel.log(string_msg(str(self.sent)))
            self.sent += 1
            delay = start + self.sent / self.hz - time.monotonic()
            if delay > 0:
                self._stop.wait(delay)

    @contextmanager
    def running(self) -> Iterator[Ticker]:
        thread = threading.Thread(target=self.run, daemon=True)
        thread.start()
        try:
            yield self
        finally:
            self._stop.set()
            thread.join()


async def test_a_capped_subscription_reads_in_holds_and_gets_fresh_messages(
    server: SdkServer,
) -> None:
    ticker = Ticker(server, 100.0)
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/tick", max_hz=5, adaptive=False) as sub:
            await wait_until(lambda: "/tick" in server.subscribed())
            lags: list[int] = []
            with ticker.running(), anyio.fail_after(20):
                async for _msg in sub:  # the first passes at once: no hold yet
                    break
                reads, received = ws.reads, sub.stats.received
                async for msg in sub:
                    lags.append(ticker.sent - 1 - int(msg.data.data))
                    if len(lags) == 8:
                        break
                reads, received = ws.reads - reads, sub.stats.received - received
            assert ws.quiet_holds >= 5
            assert received >= 100  # about 160 frames in 1.6 s
            assert reads < received / 3  # several frames per read
            # each message is about the newest the server had sent (what it
            # sent while the read and the consumer woke up aside), not the
            # oldest of the window's 20
            assert statistics.median(lags) < 10, lags
            stats = sub.stats
            queued = len(robot._conn.router._routes["/tick"][0].queue)  # type: ignore[attr-defined]
            assert stats.received == stats.delivered + stats.dropped_throttle + queued


async def test_two_clients_holds_and_capped_waits_share_one_timer_on_trio(
    server: SdkServer,
) -> None:
    """On trio the holds and the capped consumers' waits of every client on
    the loop end on one shared timer (``_trio_timers``), run by one of the
    clients and handed to the other when it closes; on asyncio every wait
    keeps its loop timer. Either way the caps deliver fresh messages."""
    trio_loop = sniffio.current_async_library() == "trio"
    timers = current_timers() if trio_loop and current_timers else None
    ticker = Ticker(server, 100.0)
    with ticker.running(), anyio.fail_after(30):
        async with rmb.connect(server.url, options=options()) as first:
            async with rmb.connect(server.url, options=options()) as second:
                fired = timers.fired if timers else 0
                if timers:
                    assert (timers.running, timers.participants) == (True, 2)
                ws = websocket_of(second)
                async with (
                    first.subscribe("/tick", max_hz=5, adaptive=False) as a,
                    second.subscribe("/tick", max_hz=5, adaptive=False) as b,
                ):
                    for sub in (a, b, a, b, a, b):
                        msg = await sub.__anext__()
                        # released at most a window (20 ticks) before it is
                        # taken here, while the other subscription is read
                        assert ticker.sent - 1 - int(msg.data.data) < 60
                holds = ws.quiet_holds
                assert holds >= 1
                if timers:
                    # each hold ended on it (the last, ended early by the
                    # unsubscribe, may still wait on the heap)
                    assert timers.fired - fired >= holds - 1
            if timers:  # the first client runs it alone now
                assert (timers.running, timers.participants) == (True, 1)
                async with first.subscribe("/tick", max_hz=5, adaptive=False) as a:
                    fired = timers.fired
                    for _ in range(3):
                        await a.__anext__()
                    assert timers.fired > fired
    if timers:
        assert (timers.running, timers.participants, len(timers)) == (False, 0, 0)


async def test_a_stopping_stream_still_delivers_its_last_message(server: SdkServer) -> None:
    ticker = Ticker(server, 50.0)
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/tick", max_hz=2, adaptive=False) as sub:
            await wait_until(lambda: "/tick" in server.subscribed())
            got: list[int] = []
            with anyio.fail_after(20):
                with ticker.running():
                    async for msg in sub:
                        got.append(int(msg.data.data))
                        if len(got) == 3:
                            break
                last = ticker.sent - 1  # the stream has stopped
                # (the third message may already be the last one sent: a
                # busy machine's ticker thread may not log again before it
                # is stopped)
                if got[-1] != last:
                    async for msg in sub:
                        got.append(int(msg.data.data))
                        if got[-1] == last:
                            break
            assert ws.quiet_holds >= 1
            assert got == sorted(got)


async def test_a_request_is_answered_without_waiting_out_a_hold() -> None:
    with SdkServer(parameters={"max_speed": 1.5}) as server:
        ticker = Ticker(server, 20.0)
        async with rmb.connect(server.url, options=options()) as robot:
            ws = websocket_of(robot)
            # a 2 s window: the reads are held for up to a second at a time
            async with robot.subscribe("/tick", max_hz=0.5, adaptive=False) as sub:
                await wait_until(lambda: "/tick" in server.subscribed())
                with ticker.running():
                    with anyio.fail_after(10):
                        await sub.__anext__()
                        await wait_until(lambda: ws.quiet_holds >= 1)
                    for _ in range(3):
                        with anyio.fail_after(0.5):  # a hold lasts up to 1 s
                            assert await robot.get_parameters(["max_speed"]) == {"max_speed": 1.5}
                        await anyio.sleep(0.1)


async def test_a_keepalive_pong_is_read_during_holds(server: SdkServer) -> None:
    ticker = Ticker(server, 20.0)
    opts = options(keepalive_interval=0.2, keepalive_timeout=0.5)
    async with rmb.connect(server.url, options=opts) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/tick", max_hz=0.5, adaptive=False) as sub:
            await wait_until(lambda: "/tick" in server.subscribed())
            with ticker.running(), anyio.fail_after(20):
                first = await sub.__anext__()
                second = await sub.__anext__()  # 2 s later: about 10 pings meanwhile
                await wait_until(lambda: ws.quiet_holds >= 1)
            assert int(second.data.data) > int(first.data.data)
            assert robot.status == "connected"


async def test_no_hold_while_a_subscription_takes_every_frame(server: SdkServer) -> None:
    ticker = Ticker(server, 50.0)
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with (
            robot.subscribe("/tick", max_hz=1, adaptive=False) as capped,
            robot.subscribe("/tick", adaptive=False) as every,
        ):
            await wait_until(lambda: "/tick" in server.subscribed())
            with ticker.running(), anyio.fail_after(20):
                n = 0
                async for _ in every:
                    n += 1
                    if n == 40:
                        break
            assert ws.quiet_holds == 0
            assert capped.stats.received == every.stats.received


async def test_a_new_subscription_ends_a_hold(server: SdkServer) -> None:
    ticker = Ticker(server, 20.0)
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/tick", max_hz=0.5, adaptive=False) as capped:
            await wait_until(lambda: "/tick" in server.subscribed())
            with ticker.running():
                with anyio.fail_after(10):
                    await capped.__anext__()
                    await wait_until(lambda: ws.quiet_holds >= 1)
                async with robot.subscribe("/tick", adaptive=False) as every:
                    with anyio.fail_after(0.5):  # a hold lasts up to 1 s
                        await every.__anext__()
                    before = ws.quiet_holds
                    n = 0
                    async for _ in every:
                        n += 1
                        if n == 10:
                            break
                    assert ws.quiet_holds == before  # none while it takes every frame


async def test_a_saturated_socket_is_read_at_once(server: SdkServer) -> None:
    """A burst larger than a hold's read (64 KiB) is read at once, not 64 KiB
    per window: holding then would only slow the server."""
    burst = server.channel("/burst", "std_msgs/msg/String")
    n = 1000  # about 1 MB, within the server's per-client backlog (1024 messages)
    async with rmb.connect(server.url, options=options()) as robot:
        ws = websocket_of(robot)
        async with robot.subscribe("/burst", max_hz=1, adaptive=False) as sub:
            await wait_until(lambda: "/burst" in server.subscribed())
            burst.log(string_msg("first"))
            with anyio.fail_after(10):
                await sub.__anext__()  # a 1 s window starts: the reads may be held
            holds = ws.quiet_holds
            for i in range(n):
                burst.log(string_msg(f"{i:04d}" + "x" * 1000))
            await wait_until(lambda: sub.stats.received == n + 1, timeout=15)
            assert ws.quiet_holds - holds <= 5
            with anyio.fail_after(5):
                last = await sub.__anext__()
            assert last.data.data.startswith(f"{n - 1:04d}")
