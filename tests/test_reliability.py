"""The reliability layer wired into the Client, against the real Foxglove SDK
server: the adaptive throttle ahead of decoding, the circuit breaker removing
and restoring the subscription at the bridge, the control outbox under a
flood, the lag monitor's lifetime, and the idle latency probe.

Lag is injected into this event loop's monitor (``LagMonitor.record``, three
samples, since one alone is a stall the throttle ignores), so
the tests assert what the layer does with a given lag, not how fast the
machine is."""

from __future__ import annotations

import threading
from functools import partial

import anyio

import ros_mobile_bridge as rmb
from _util import fast_options, wait_until
from peers.foxglove_sdk import SdkServer, decode, image_msg, string_msg
from ros_mobile_bridge.flow import current_monitor

QUICK_BREAKER = rmb.BreakerPolicy(
    cooldowns_s=(1.5, 3.0), saturation_ms=250, dwell_s=0.0, warmup_s=0.0, probe_s=0.3
)


def saturate(lag_ms: float) -> None:
    """Inject a recurring lag: three samples, as a busy loop gives (one
    sample alone is a stall, which the throttle ignores)."""
    for _ in range(3):
        current_monitor().record(lag_ms)


options = partial(fast_options, connect_timeout=10.0, zero_twist_on_exit=False)


async def test_adaptive_throttle_caps_a_subscription_ahead_of_decoding(server: SdkServer) -> None:
    chatter = server.channel("/fast", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(breaker=None)) as robot:
        async with (
            robot.subscribe("/fast", buffer=100) as adaptive,
            robot.subscribe("/fast", adaptive=False, buffer=100) as fixed,
        ):
            await wait_until(lambda: "/fast" in server.subscribed())
            saturate(200.0)  # a recurring 200 ms lag: "auto" goes to its 4 Hz bucket
            for i in range(40):
                chatter.log(string_msg(f"m{i}"))
            await wait_until(lambda: fixed.stats.received == 40 and adaptive.stats.received == 40)
            stats = adaptive.stats
            assert stats.bucket == "4 Hz"
            assert stats.effective_interval_ms == 250.0
            # a burst inside one 250 ms window: the first frame and the newest
            assert stats.dropped_throttle == 38
            assert fixed.stats.dropped_throttle == 0
            assert fixed.stats.bucket == ""
            with anyio.fail_after(5):
                first = await adaptive.__anext__()
                last = await adaptive.__anext__()
            assert (first.data.data, last.data.data) == ("m0", "m39")
            assert adaptive.stats.delivered == 2  # only two were ever decoded
            assert adaptive.stats.arrival_bytes_per_s >= 0.0


async def test_throttle_mode_callable_is_read_on_every_message(server: SdkServer) -> None:
    chatter = server.channel("/m", "std_msgs/msg/String")
    mode = ["performance"]
    async with rmb.connect(
        server.url, options=options(breaker=None, throttle_mode=lambda: mode[0])
    ) as robot:
        async with robot.subscribe("/m", buffer=100) as sub:
            await wait_until(lambda: "/m" in server.subscribed())
            saturate(60.0)
            chatter.log(string_msg("a"))
            await wait_until(lambda: sub.stats.received == 1)
            assert sub.stats.bucket == "30 Hz"  # performance at 60 ms
            mode[0] = "efficient"
            chatter.log(string_msg("b"))
            await wait_until(lambda: sub.stats.received == 2)
            assert sub.stats.bucket == "2 Hz"  # efficient at 60 ms, applied at once


async def test_breaker_trips_removes_the_subscription_at_the_bridge_and_recovers(
    server: SdkServer,
) -> None:
    chatter = server.channel("/cam", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(breaker=QUICK_BREAKER)) as robot:
        async with robot.subscribe("/cam") as sub:
            seen: list[str] = []

            async def watch() -> None:
                async for state in sub.breaker.watch():
                    seen.append(state)

            async with anyio.create_task_group() as tg:
                tg.start_soon(watch)
                await wait_until(lambda: "/cam" in server.subscribed())
                saturate(1000.0)  # saturated, at the deepest bucket
                await wait_until(lambda: sub.breaker.state == "tripped_auto", what="trip")
                assert sub.breaker.next_retry_at is not None
                # no frames cross the network while tripped
                await wait_until(lambda: "/cam" in server.recorder.unsubscribed, what="unsubscribe")
                before = sub.stats.received
                chatter.log(string_msg("while tripped"))
                await anyio.sleep(0.1)
                assert sub.stats.received == before
                # cooldown (longer than the 1 s lag window), half-open (subscribed
                # again), a healthy probe, closed
                await wait_until(lambda: sub.breaker.state == "half_open", what="half-open")
                await wait_until(lambda: server.subscribed().count("/cam") == 2, what="resubscribe")
                await wait_until(lambda: sub.breaker.state == "closed", what="closed", timeout=5)
                chatter.log(string_msg("after"))
                with anyio.fail_after(5):
                    msg = await sub.__anext__()
                assert msg.data.data == "after"
                tg.cancel_scope.cancel()
            assert seen[:4] == ["closed", "tripped_auto", "half_open", "closed"]
            assert sub.breaker.trips == 1


async def test_breaker_disable_and_retry_by_hand(server: SdkServer) -> None:
    server.channel("/cam", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(breaker=None)) as robot:
        async with robot.subscribe("/cam") as sub:
            await wait_until(lambda: "/cam" in server.subscribed())
            sub.breaker.disable()
            assert sub.breaker.state == "tripped_manual"
            assert sub.breaker.next_retry_at is None
            await wait_until(lambda: "/cam" in server.recorder.unsubscribed, what="unsubscribe")
            sub.breaker.retry()
            await wait_until(lambda: server.subscribed().count("/cam") == 2, what="resubscribe")


async def test_another_local_subscriber_keeps_the_topic_while_one_breaker_is_tripped(
    server: SdkServer,
) -> None:
    chatter = server.channel("/shared", "std_msgs/msg/String")
    async with rmb.connect(server.url, options=options(breaker=None)) as robot:
        async with robot.subscribe("/shared") as a, robot.subscribe("/shared") as b:
            await wait_until(lambda: "/shared" in server.subscribed())
            a.breaker.disable()
            await wait_until(lambda: a._queue.blocked, what="a blocked")
            chatter.log(string_msg("x"))
            await wait_until(lambda: b.stats.received == 1)
            assert a.stats.dropped_breaker == 1 and a.stats.delivered == 0
            assert "/shared" not in server.recorder.unsubscribed


async def test_control_frame_leaves_ahead_of_queued_data_under_an_image_flood(
    server: SdkServer,
) -> None:
    cam = server.channel("/camera", "sensor_msgs/msg/Image")
    image = image_msg()
    stop = threading.Event()

    def flood() -> None:
        while not stop.is_set():
            cam.log(image)

    thread = threading.Thread(target=flood)
    try:
        async with rmb.connect(server.url, options=options(breaker=None)) as robot:
            await robot.advertise("/log", "std_msgs/msg/String")
            await robot.advertise("/cmd_vel", "geometry_msgs/msg/Twist")
            async with robot.subscribe("/camera", adaptive=False) as sub:
                thread.start()
                await wait_until(lambda: sub.stats.received > 5, what="the flood")
                backend = robot._conn.adapter
                # 200 data frames queued, then 5 control values for one topic,
                # all without yielding: the writer sees the whole backlog
                for i in range(200):
                    await robot._conn.outbound.outbox.put_data(
                        "/log", backend.encode_publish("/log", {"data": str(i)})
                    )
                for x in range(5):
                    robot._conn.outbound.outbox.put_control(
                        "/cmd_vel", backend.encode_publish("/cmd_vel", {"linear": {"x": float(x)}})
                    )
                consumed = 0
                with anyio.fail_after(10):
                    async for _ in sub:  # keep ingesting images meanwhile
                        consumed += 1
                        if len(server.messages("/log")) == 200:
                            break
        order = [m.topic for m in server.messages()]
    finally:
        stop.set()
        if thread.is_alive():
            thread.join()
    cmd = [decode("geometry_msgs/msg/Twist", m.data).linear.x for m in server.messages("/cmd_vel")]
    assert cmd == [4.0]  # five queued control values went out as one, the newest
    assert order.index("/cmd_vel") < len(order) - 1
    logs_before_cmd = order[: order.index("/cmd_vel")].count("/log")
    assert logs_before_cmd <= 1  # at most the frame already being written
    assert consumed > 0


async def test_lag_monitor_runs_while_a_client_is_open(server: SdkServer) -> None:
    monitor = current_monitor()
    async with rmb.connect(server.url, options=options()):
        await wait_until(lambda: monitor.sampling, what="sampling")
        n = len(monitor)
        await wait_until(lambda: len(monitor) > n + 2, what="samples")
        assert rmb.lag.stats().count >= 1
    await wait_until(lambda: not monitor.sampling, what="sampling stops with the last client")


async def test_clients_on_one_loop_share_one_tick(server: SdkServer) -> None:
    """Each client with a subscription registers one callback with the
    loop's one sampler (no timer of its own); an idle client none, and a
    client removes it when its last subscription ends or it closes; a
    breaker still trips through the shared tick."""
    monitor = current_monitor()
    before = monitor.ticks
    async with (
        rmb.connect(server.url, options=options()) as a,
        rmb.connect(server.url, options=options()) as b,
    ):
        await wait_until(lambda: monitor.sampling, what="sampling")
        await anyio.wait_all_tasks_blocked()  # every client's tasks run and wait
        assert monitor.ticks == before  # idle clients: nothing to check
        async with a.subscribe("/log") as sub:
            assert monitor.ticks == before + 1
            async with a.subscribe("/log") as again, b.subscribe("/log"):
                assert monitor.ticks == before + 2  # one per client, not per subscription
                again.close()
            assert monitor.ticks == before + 1
            sub.breaker.disable()
            assert sub.breaker.state == "tripped_manual"
            await wait_until(lambda: sub._queue.blocked, what="the tick applied the trip")
        assert monitor.ticks == before
        async with b.subscribe("/log"):
            assert monitor.ticks == before + 1
        assert b.connected
    assert monitor.ticks == before


async def test_idle_latency_probe_reports_ping_round_trips(server: SdkServer) -> None:
    rtts: list[float] = []
    opts = options(keepalive_interval=0.05, on_latency=rtts.append)
    async with rmb.connect(server.url, options=opts):
        await wait_until(lambda: len(rtts) >= 3, what="three round trips")
    assert all(r >= 0 for r in rtts)
