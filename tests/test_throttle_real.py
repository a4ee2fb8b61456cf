"""The adaptive throttle against the real condition it exists for: a camera
stream (640x480 rgb8 Images at 30 Hz from the official Foxglove SDK server)
into a default ``subscribe()`` while the event loop is really blocked, once
or again and again. No lag is injected: the lag monitor measures the loop.

- One stall of a second (user code blocking the loop once) loses nothing:
  the frames queued behind it already crossed the socket.
- A new image subscriber (its own connection, so its own decoder build on
  the first message) loses nothing.
- A loop busy 85 % of the time still tightens the throttle within about a
  second, logs the change at INFO, and relaxes once the loop is calm.
- ``save_bandwidth="adaptive"`` pauses the server's stream between
  deliveries while that loop is busy, and not while it is calm.

Frames carry their sequence number in ``header.stamp.sec``, so the tests
count exactly which frames arrived."""

from __future__ import annotations

import logging
import struct
import threading
import time
from functools import partial

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.foxglove_sdk import SdkServer, image_msg
from ros_mobile_bridge.flow import current_monitor

RATE_HZ = 30.0


class Camera:
    """Publishes ``count`` images at 30 Hz from a thread (the server runs in
    this process, its I/O on its own threads; a blocked event loop does not
    stop it, as a robot would not stop)."""

    def __init__(self, server: SdkServer, topic: str = "/camera") -> None:
        self.channel = server.channel(topic, "sensor_msgs/msg/Image")
        self.template = bytearray(image_msg())
        self.sent = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self, count: int) -> None:
        def run() -> None:
            start = time.monotonic()
            for seq in range(count):
                if self._stop.is_set():
                    return
                delay = start + seq / RATE_HZ - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                payload = bytearray(self.template)
                struct.pack_into("<i", payload, 4, seq)  # header.stamp.sec
                self.channel.log(bytes(payload))
                self.sent = seq + 1

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    @property
    def done(self) -> bool:
        return self._thread is not None and not self._thread.is_alive()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10)


async def busy_loop(busy: anyio.Event, calm: anyio.Event) -> None:
    """From ``busy`` until ``calm``, block the event loop 85 % of the time."""
    await busy.wait()
    while not calm.is_set():
        time.sleep(0.085)
        await anyio.sleep(0.015)


options = partial(rmb.ClientOptions, zero_twist_on_exit=False)


def dropped(stats: rmb.SubscriptionStats) -> dict[str, int]:
    return {
        "throttle": stats.dropped_throttle,
        "conflated": stats.dropped_conflated,
        "overflow": stats.dropped_overflow,
        "breaker": stats.dropped_breaker,
    }


NONE_DROPPED = {"throttle": 0, "conflated": 0, "overflow": 0, "breaker": 0}


async def test_one_stall_of_a_second_loses_no_camera_frame(server: SdkServer) -> None:
    camera = Camera(server)
    count = 120  # 4 s at 30 Hz
    seen: list[int] = []
    stalled_lag = 0.0
    try:
        async with (
            rmb.connect(server.url, options=options()) as robot,
            robot.subscribe("/camera") as sub,
        ):
            await wait_until(lambda: "/camera" in server.subscribed(), what="subscribed")
            camera.start(count)
            # 4 s of stream and a 1 s stall: whatever has not arrived 6 s
            # later was lost (the counters below say where)
            with anyio.move_on_after(10):
                async for msg in sub:
                    seen.append(int(msg.data.header.stamp.sec))
                    if len(seen) == 30:
                        time.sleep(1.0)  # user code blocks the loop once
                        # the sampler records the stall (its next sample; it
                        # shows for a second)
                        stalled_lag = await wait_until(
                            lambda: (lag := current_monitor().max_lag_ms()) >= 900.0 and lag,
                            what="the stall in the lag monitor",
                        )
                    if len(seen) == count:
                        break
            stats = sub.stats
    finally:
        camera.stop()
    assert stalled_lag >= 900.0  # the stall really happened and was measured
    assert seen == list(range(count))  # every frame, in order
    assert dropped(stats) == NONE_DROPPED
    assert stats.bucket == "full rate"
    assert sub._throttle is not None and sub._throttle.transitions == 0


async def test_a_new_image_subscriber_loses_nothing_to_its_first_decode(
    server: SdkServer,
) -> None:
    camera = Camera(server)
    count = 90  # 3 s at 30 Hz
    first: list[int] = []
    second: list[int] = []
    try:
        async with (
            rmb.connect(server.url, options=options()) as robot,
            robot.subscribe("/camera") as sub,
        ):
            await wait_until(lambda: "/camera" in server.subscribed(), what="subscribed")
            camera.start(count)
            async with anyio.create_task_group() as tg:

                async def consume(s: rmb.Subscription, into: list[int]) -> None:
                    async for msg in s:
                        into.append(int(msg.data.header.stamp.sec))
                        if into[-1] == count - 1:
                            return

                tg.start_soon(consume, sub, first)
                await wait_until(lambda: len(first) >= 15, what="the stream")
                # a second client joins mid-stream: its own connection and
                # codec, so its decoder is built for its first frame
                async with (
                    rmb.connect(server.url, options=options()) as late,
                    late.subscribe("/camera") as late_sub,
                ):
                    with anyio.fail_after(20):
                        await consume(late_sub, second)
                    late_stats = late_sub.stats
                await wait_until(
                    lambda: first and first[-1] == count - 1,
                    20,
                    what="the first subscriber's last frame",
                    interval=0.05,
                )
            stats = sub.stats
    finally:
        camera.stop()
    assert first == list(range(count))
    assert dropped(stats) == NONE_DROPPED
    assert second, "the late subscriber received nothing"
    assert second == list(range(second[0], count))  # from its first frame on, every one
    assert dropped(late_stats) == NONE_DROPPED
    assert late_stats.bucket == "full rate"


async def test_a_loop_busy_85_percent_tightens_within_about_a_second_then_relaxes(
    server: SdkServer, caplog: pytest.LogCaptureFixture
) -> None:
    camera = Camera(server)
    logger = logging.getLogger("tests.throttle_real")
    busy = anyio.Event()
    calm = anyio.Event()
    tightened_after: list[float] = []
    try:
        with caplog.at_level(logging.INFO, logger=logger.name):
            async with (
                rmb.connect(server.url, options=options(logger=logger, breaker=None)) as robot,
                robot.subscribe("/camera") as sub,
                anyio.create_task_group() as tg,
            ):
                await wait_until(lambda: "/camera" in server.subscribed(), what="subscribed")
                camera.start(int(RATE_HZ * 30))

                async def consume() -> None:
                    async for _ in sub:
                        pass

                tg.start_soon(consume)
                tg.start_soon(busy_loop, busy, calm)
                await wait_until(lambda: sub.stats.delivered >= 30, what="the stream")
                assert sub.stats.bucket == "full rate"
                start = time.monotonic()
                busy.set()
                await wait_until(
                    lambda: sub.stats.bucket != "full rate", timeout=10, what="tightening"
                )
                tightened_after.append(time.monotonic() - start)
                throttled = sub.stats.dropped_throttle
                await wait_until(
                    lambda: sub.stats.dropped_throttle > throttled + 3,
                    timeout=10,
                    what="frames dropped ahead of decoding",
                )
                calm.set()
                await wait_until(
                    lambda: sub.stats.bucket == "full rate", timeout=15, what="relaxing"
                )
                tg.cancel_scope.cancel()
    finally:
        camera.stop()
    # "about a second": three samples of a loop this busy take ~0.3 s; the
    # bound leaves room for a loaded test machine
    assert tightened_after[0] < 2.5
    changes = [r.getMessage() for r in caplog.records if r.getMessage().startswith("throttle ")]
    assert any("/camera: full rate ->" in line and "recurring" in line for line in changes)
    assert any("-> full rate" in line for line in changes)


async def test_adaptive_save_bandwidth_pauses_the_stream_while_the_loop_is_busy(
    server: SdkServer,
) -> None:
    """``save_bandwidth="adaptive"`` without ``max_hz``: while the loop is
    calm the server's stream is whole (no pause, every frame in order); a
    loop busy 85 % of the time tightens the throttle and the client starts
    unsubscribing between deliveries, so the server stops sending; once the
    loop is calm again the stream is whole again."""
    camera = Camera(server)
    busy = anyio.Event()
    calm = anyio.Event()
    seqs: list[int] = []
    try:
        async with (
            rmb.connect(server.url, options=options(breaker=None)) as robot,
            robot.subscribe("/camera", save_bandwidth="adaptive") as sub,
            anyio.create_task_group() as tg,
        ):
            await wait_until(lambda: "/camera" in server.subscribed(), what="subscribed")
            camera.start(int(RATE_HZ * 60))

            async def consume() -> None:
                async for msg in sub:
                    seqs.append(msg.data.header.stamp.sec)

            tg.start_soon(consume)
            tg.start_soon(busy_loop, busy, calm)
            await wait_until(lambda: len(seqs) >= 30, timeout=10, what="the stream")
            # calm: one subscription, never paused, every frame
            assert server.unsubscribed().count("/camera") == 0
            assert seqs == list(range(seqs[0], seqs[0] + len(seqs)))
            busy.set()
            await wait_until(
                lambda: server.unsubscribed().count("/camera") >= 3,
                timeout=15,
                what="the stream paused between deliveries",
            )
            assert sub.stats.bucket != "full rate"
            assert server.subscribed().count("/camera") >= 3  # and resumed each time
            calm.set()
            await wait_until(lambda: sub.stats.bucket == "full rate", timeout=20, what="relaxing")
            # whole again once the relaxed rate reaches the adapter (the
            # router's next tick; a resumption or two may pause once more):
            # then 30 frames in a row without a pause, each in order
            for _ in range(5):
                paused = server.unsubscribed().count("/camera")
                start = len(seqs)
                await wait_until(lambda s=start: len(seqs) >= s + 31, timeout=10, what="frames")
                if server.unsubscribed().count("/camera") == paused:
                    break
            else:
                raise AssertionError("the stream still pauses after the loop is calm")
            tail = seqs[start + 1 :]  # the first may follow a pause
            assert tail == list(range(tail[0], tail[0] + len(tail)))
            tg.cancel_scope.cancel()
    finally:
        camera.stop()
