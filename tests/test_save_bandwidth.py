"""``save_bandwidth`` and ``bytes_received`` against the real Foxglove SDK
server (foxglove-sdk), in-process, on asyncio and trio.

The server sends every message of a subscribed channel (the protocol has no
rate option); in the bandwidth mode the client unsubscribes after each
message and subscribes again when the next one is due. A server that replays
the latest message to a new subscriber (foxglove_bridge does for
transient-local topics) is the SDK server with a listener that logs the
topic's latest message from ``on_subscribe``: the SDK's own server, sending
a real message to the subscription just made."""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from typing import Any

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import FAST, take, wait_port_free, wait_until, wait_until_sync
from _util import fast_options as options
from peers.foxglove_sdk import SdkServer, _Listener, image_msg, string_msg

STRING = "std_msgs/msg/String"


class _Replaying(_Listener):
    """Logs the topic's latest message again to a new subscription, as a
    transient-local topic's bridge does."""

    def on_subscribe(self, client: Any, channel: Any) -> None:
        super().on_subscribe(client, channel)
        server = self.s
        assert isinstance(server, ReplayingServer)
        with server.latest_lock:
            latest = server.latest.get(channel.topic)
        if latest is not None:
            server.channels[channel.topic].log(latest[0], log_time=latest[1])


class ReplayingServer(SdkServer):
    def __init__(self, **kw: Any) -> None:
        self.latest_lock = threading.Lock()
        self.latest: dict[str, tuple[bytes, int]] = {}
        self.channels: dict[str, Any] = {}
        super().__init__(listener=_Replaying, **kw)

    def publish(self, topic: str, payload: bytes) -> None:
        """Log ``payload`` on ``topic`` and keep it as the latest."""
        if topic not in self.channels:
            self.channels[topic] = self.channel(topic, STRING)
        stamp = time.time_ns()
        with self.latest_lock:
            self.latest[topic] = (payload, stamp)
        self.channels[topic].log(payload, log_time=stamp)


@pytest.fixture
def replaying() -> Iterator[ReplayingServer]:
    srv = ReplayingServer()
    try:
        yield srv
    finally:
        srv.stop()


def fates(stats: rmb.SubscriptionStats) -> int:
    """The frames whose fate is decided (all of them, once nothing is queued)."""
    return (
        stats.delivered
        + stats.dropped_throttle
        + stats.dropped_conflated
        + stats.dropped_overflow
        + stats.dropped_breaker
        + stats.dropped_replay
    )


def subscribes(server: SdkServer, topic: str) -> int:
    return server.subscribed().count(topic)


def unsubscribes(server: SdkServer, topic: str) -> int:
    return server.unsubscribed().count(topic)


# -- arguments ------------------------------------------------------------------


async def test_the_mode_needs_a_rate_and_is_checked_at_once(server: SdkServer) -> None:
    server.channel("/a", STRING)
    async with rmb.connect(server.url, options=options()) as robot:
        with pytest.raises(ValueError, match="needs max_hz"):
            robot.subscribe("/a", save_bandwidth=True)
        with pytest.raises(ValueError, match="needs max_hz or adaptive=True"):
            robot.subscribe("/a", save_bandwidth="adaptive", adaptive=False)
        with pytest.raises(ValueError, match="True, False or 'adaptive'"):
            robot.subscribe("/a", max_hz=5, save_bandwidth="yes")  # type: ignore[arg-type]
        with pytest.raises(TypeError, match="bool or 'adaptive'"):
            robot.subscribe("/a", max_hz=5, save_bandwidth=1)  # type: ignore[arg-type]
        # accepted: a cap, or the adaptive throttle alone
        async with robot.subscribe("/a", max_hz=5, save_bandwidth=True):
            pass
        async with robot.subscribe("/a", save_bandwidth="adaptive"):
            pass
    assert robot.status == "closed"


# -- the mode on the wire -------------------------------------------------------


@pytest.mark.parametrize("mode", [True, "adaptive"])
async def test_the_stream_pauses_after_each_message_and_resumes_on_the_max_hz_schedule(
    server: SdkServer, mode: rmb.SaveBandwidth
) -> None:
    """``"adaptive"`` pauses on the cap as well while the loop does not lag
    (the adaptive interval is then 0)."""
    chatter = server.channel("/p", STRING)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/p", max_hz=20, save_bandwidth=mode) as sub:
            await wait_until(lambda: subscribes(server, "/p") == 1)
            got: list[str] = []
            for round_ in range(3):
                chatter.log(string_msg(f"m{round_}"))
                with anyio.fail_after(5):
                    got.append((await sub.__anext__()).data.data)
                # taken: the client unsubscribes, then subscribes again when due
                await wait_until(lambda r=round_: unsubscribes(server, "/p") == r + 1)
                await wait_until(lambda r=round_: subscribes(server, "/p") == r + 2)
            assert sub.state == "active"  # paused or not, the topic is carried
    assert got == ["m0", "m1", "m2"]
    stats = sub.stats
    assert stats.received == stats.delivered == 3 and stats.dropped_replay == 0
    assert stats.bytes_received == sum(len(string_msg(f"m{i}")) for i in range(3))


async def test_a_replay_on_resubscription_is_skipped_and_counted(
    replaying: ReplayingServer,
) -> None:
    replaying.channels["/latched"] = replaying.channel("/latched", STRING)
    async with rmb.connect(replaying.url, options=options()) as robot:
        async with robot.subscribe(
            "/latched", max_hz=20, save_bandwidth=True, adaptive=False
        ) as sub:
            await wait_until(lambda: subscribes(replaying, "/latched") == 1)
            replaying.publish("/latched", string_msg("first"))
            with anyio.fail_after(5):
                first = await sub.__anext__()
            # the client pauses, resumes, and the server replays "first": skipped
            await wait_until(lambda: sub.stats.dropped_replay == 1, what="the replay skipped")
            assert subscribes(replaying, "/latched") == 2
            # a replay does not pause the stream: the next message arrives at once
            replaying.publish("/latched", string_msg("second"))
            with anyio.fail_after(5):
                second = await sub.__anext__()
            await wait_until(lambda: sub.stats.dropped_replay == 2, what="the next replay")
    assert (first.data.data, second.data.data) == ("first", "second")
    stats = sub.stats
    assert stats.delivered == 2 and stats.dropped_replay == 2
    assert stats.received == fates(stats) == 4
    assert stats.bytes_received == 2 * len(string_msg("first")) + 2 * len(string_msg("second"))


async def test_a_stream_of_identical_messages_is_delivered_on_schedule(server: SdkServer) -> None:
    """Only the first message after a resubscription is checked for a
    replay: a topic that publishes the same bytes again and again (a
    status without a stamp, a camera on a still scene with a fixed stamp)
    loses at most one message per resubscription, never the stream."""
    chatter = server.channel("/same", STRING)
    payload = string_msg("ok")
    stop = threading.Event()

    def publish() -> None:
        while not stop.wait(0.01):  # 100 Hz
            chatter.log(payload)

    thread = threading.Thread(target=publish, daemon=True)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/same", max_hz=20, save_bandwidth=True, adaptive=False) as sub:
            thread.start()
            try:
                got = await take(sub, 4, timeout=10)
                await wait_until(lambda: subscribes(server, "/same") >= 4)
            finally:
                stop.set()
                thread.join()
    assert [m.data.data for m in got] == ["ok"] * 4
    stats = sub.stats
    # one check per resubscription: at most one skipped each time
    assert stats.dropped_replay <= subscribes(server, "/same") - 1


async def test_the_default_mode_delivers_a_replay_again(replaying: ReplayingServer) -> None:
    """Without the mode there is no resubscription and so no replay; the
    first subscription's replay is a message like any other."""
    replaying.channels["/l"] = replaying.channel("/l", STRING)
    replaying.publish("/l", string_msg("before"))
    async with rmb.connect(replaying.url, options=options()) as robot:
        async with robot.subscribe("/l", max_hz=20, save_bandwidth=True) as sub:
            with anyio.fail_after(5):
                msg = await sub.__anext__()
    assert msg.data.data == "before" and sub.stats.dropped_replay == 0


async def test_a_stopping_stream_last_message_the_default_gets_and_the_mode_may_miss(
    server: SdkServer,
) -> None:
    """The price of the mode, shown with the same sequence in both modes: a
    message published while the stream is paused (here: after the client
    unsubscribed, before it subscribed again) is never sent. The default
    mode's trailing delivery hands it over."""
    results: dict[bool, list[str]] = {}
    async with rmb.connect(server.url, options=options()) as robot:
        for mode in (False, True):
            topic = f"/stop_{mode}"
            chatter = server.channel(topic, STRING)
            async with robot.subscribe(topic, max_hz=4, adaptive=False, save_bandwidth=mode) as sub:
                await wait_until(lambda t=topic: subscribes(server, t) == 1)
                chatter.log(string_msg("first"))
                got = [(await sub.__anext__()).data.data]
                if mode:  # paused: the server has stopped sending
                    await wait_until(lambda t=topic: unsubscribes(server, t) == 1)
                chatter.log(string_msg("last"))  # the stream stops here
                if mode:
                    # resumed; nothing was sent meanwhile. A later message proves it
                    await wait_until(lambda t=topic: subscribes(server, t) == 2)
                    chatter.log(string_msg("later"))
                with anyio.fail_after(5):
                    got.append((await sub.__anext__()).data.data)
                results[mode] = got
                assert sub.stats.received == fates(sub.stats) == 2
    assert results[False] == ["first", "last"]
    assert results[True] == ["first", "later"]


async def test_a_second_subscription_without_the_mode_keeps_the_stream_whole(
    server: SdkServer,
) -> None:
    chatter = server.channel("/both", STRING)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/both", max_hz=20, save_bandwidth=True) as saving:
            await wait_until(lambda: subscribes(server, "/both") == 1)
            chatter.log(string_msg("a"))
            with anyio.fail_after(5):
                await saving.__anext__()
            await wait_until(lambda: subscribes(server, "/both") == 2, what="resumed")
            async with robot.subscribe("/both") as whole:
                for i in range(5):
                    chatter.log(string_msg(f"w{i}"))
                got = [msg.data.data for msg in await take(whole, 5, timeout=5)]
            assert got == [f"w{i}" for i in range(5)]
            # no pause while the whole stream is wanted
            assert unsubscribes(server, "/both") == 1


async def test_unsubscribing_while_paused_leaves_no_server_subscription(server: SdkServer) -> None:
    chatter = server.channel("/gone", STRING)
    async with rmb.connect(server.url, options=options()) as robot:
        async with robot.subscribe("/gone", max_hz=10, save_bandwidth=True) as sub:
            await wait_until(lambda: subscribes(server, "/gone") == 1)
            chatter.log(string_msg("x"))
            with anyio.fail_after(5):
                await sub.__anext__()
            await wait_until(lambda: unsubscribes(server, "/gone") == 1, what="paused")
        # left while paused: the resumption (due 100 ms after) never comes
        await anyio.sleep(0.5)
        assert subscribes(server, "/gone") == 1
        assert unsubscribes(server, "/gone") == 1
        assert not chatter.has_sinks()
    assert robot.status == "closed"


async def test_closing_the_client_while_paused_ends_the_iteration(server: SdkServer) -> None:
    chatter = server.channel("/close", STRING)
    got: list[str] = []
    async with rmb.connect(server.url, options=options()) as robot:
        sub = await robot.subscribe("/close", max_hz=1, save_bandwidth=True).__aenter__()
        await wait_until(lambda: subscribes(server, "/close") == 1)
        chatter.log(string_msg("only"))
        with anyio.fail_after(5):
            got.append((await sub.__anext__()).data.data)
        await wait_until(lambda: unsubscribes(server, "/close") == 1, what="paused")
    # the client closed with the subscription paused (resumption due in 1 s)
    with anyio.fail_after(5):
        rest = [msg async for msg in sub]
    assert got == ["only"] and rest == []
    assert robot.status == "closed"
    assert subscribes(server, "/close") == 1


async def test_a_paused_subscription_resumes_after_a_reconnect() -> None:
    first = SdkServer()
    port = first.port
    chatter = first.channel("/r", STRING)
    second: SdkServer | None = None
    try:
        async with rmb.connect(first.url, options=options(reconnect=FAST)) as robot:
            async with robot.subscribe("/r", max_hz=10, save_bandwidth=True) as sub:
                await wait_until(lambda: subscribes(first, "/r") == 1)
                chatter.log(string_msg("before"))
                with anyio.fail_after(5):
                    assert (await sub.__anext__()).data.data == "before"
                await wait_until(lambda: unsubscribes(first, "/r") == 1, what="paused")
                first.stop()
                await wait_until(lambda: robot.status == "reconnecting", 10)
                await wait_port_free(port)
                second = SdkServer(port=port)
                chatter2 = second.channel("/r", STRING)
                await wait_until(lambda: robot.status == "connected", 10, "reconnected")
                await wait_until(lambda: subscribes(second, "/r") == 1, 10, "restored")
                got = []
                for i in range(2):  # and it pauses and resumes on the new connection
                    chatter2.log(string_msg(f"after{i}"))
                    with anyio.fail_after(5):
                        got.append((await sub.__anext__()).data.data)
                    await wait_until(lambda i=i: subscribes(second, "/r") == i + 2)
                assert got == ["after0", "after1"]
                assert unsubscribes(second, "/r") == 2
    finally:
        first.stop()
        if second is not None:
            second.stop()
    assert robot.status == "closed"


# -- bytes received ---------------------------------------------------------------


async def test_bytes_received_per_subscription_and_per_connection(server: SdkServer) -> None:
    camera = server.channel("/image", "sensor_msgs/msg/Image")
    chatter = server.channel("/s", STRING)
    image = image_msg(64, 48)
    async with rmb.connect(server.url, options=options()) as robot:
        start = robot.stats()
        assert start.bytes_received > 0 and start.messages_received >= 1  # the greeting
        async with robot.subscribe("/image", buffer=8) as images, robot.subscribe("/s") as texts:
            await wait_until(lambda: subscribes(server, "/image") == subscribes(server, "/s") == 1)
            for i in range(4):
                camera.log(image)
                chatter.log(string_msg(f"t{i}"))
            await wait_until(lambda: images.stats.received == 4 and texts.stats.received == 4)
            end = robot.stats()
    assert images.stats.bytes_received == 4 * len(image)
    assert texts.stats.bytes_received == sum(len(string_msg(f"t{i}")) for i in range(4))
    payloads = images.stats.bytes_received + texts.stats.bytes_received
    # eight messageData frames: 13 header bytes each, plus WebSocket framing
    # (2 to 10 bytes: unmasked server frames) and the subscribe answers
    grew = end.bytes_received - start.bytes_received
    assert payloads + 8 * (13 + 2) <= grew
    assert end.messages_received - start.messages_received >= 8
    assert isinstance(end, rmb.ConnectionStats)


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_the_sync_client_mirrors_the_mode_and_the_stats(server: SdkServer, backend: str) -> None:
    chatter = server.channel("/sync", STRING)
    with rmb.connect_sync(server.url, backend=backend, options=options()) as robot:  # type: ignore[arg-type]
        with pytest.raises(ValueError, match="needs max_hz"):
            robot.subscribe("/sync", save_bandwidth=True)
        with robot.subscribe("/sync", max_hz=10, save_bandwidth=True, timeout=5) as sub:
            wait_until_sync(lambda: subscribes(server, "/sync") >= 1, 5, what="the subscribe")
            chatter.log(string_msg("s"))
            msg = sub.get()
            stats = sub.stats
        conn = robot.stats()
    assert msg.data.data == "s"
    assert stats.bytes_received == len(string_msg("s")) and stats.delivered == 1
    assert conn.bytes_received > stats.bytes_received and conn.messages_received >= 2
