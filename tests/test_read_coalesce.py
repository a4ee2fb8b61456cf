"""Read coalescing (``ClientOptions.read_coalesce``) against the real condition
it exists for: a steady stream of small messages from the official Foxglove
SDK server, published from a thread at a fixed rate, into ``async for``.

Under a 1 kHz stream the reader waits up to the window before reading again,
so several frames are read and handed over at one wake-up, and every message
still arrives, in order. A slow stream (one message per 100 ms, slower than
the window) is read as it arrives: nothing waits. With
``read_coalesce=0`` no read ever waits. The transport counts its reads
(``WebSocket.reads``) and the reads that waited first
(``WebSocket.coalesced``); the tests assert those counts, not timings."""

from __future__ import annotations

import threading
import time
from functools import partial

import anyio
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.foxglove_sdk import SdkServer, string_msg
from ros_mobile_bridge.transport import WebSocket

TOPIC = "/chatter"


options = partial(rmb.ClientOptions, zero_twist_on_exit=False, keepalive_interval=0)


def websocket(robot: rmb.Client) -> WebSocket:
    ws = robot._conn.adapter._ws  # type: ignore[attr-defined]
    assert isinstance(ws, WebSocket)
    return ws


class Talker:
    """Publishes ``count`` Strings ``"0"``, ``"1"``, ... at ``hz`` from a thread
    on a fixed schedule (the server's I/O runs on its own threads)."""

    def __init__(self, server: SdkServer, count: int, hz: float) -> None:
        self.channel = server.channel(TOPIC, "std_msgs/msg/String")
        self.count = count
        self.hz = hz
        self.thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        start = time.monotonic()
        for seq in range(self.count):
            delay = start + seq / self.hz - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            self.channel.log(string_msg(str(seq)))

    def start(self) -> None:
        self.thread.start()

    def join(self) -> None:
        self.thread.join(timeout=30)


async def receive(
    server: SdkServer, count: int, hz: float, window: float, held: list[int] | None = None
) -> tuple[int, int]:
    """Stream ``count`` messages at ``hz`` into a client with
    ``read_coalesce=window``; check every one arrived in order; return the
    reads and the waiting reads the stream took."""
    talker = Talker(server, count, hz)
    async with (
        rmb.connect(server.url, options=options(read_coalesce=window)) as robot,
        robot.subscribe(TOPIC, buffer=count) as sub,
    ):
        ws = websocket(robot)
        await wait_until(lambda: TOPIC in server.subscribed(), what="the server's subscription")
        reads, waited, direct, paced = ws.reads, ws.coalesced, ws.held_reads, ws.paced_reads
        talker.start()
        got: list[str] = []
        with anyio.fail_after(30):
            async for msg in sub:
                got.append(msg.data.data)
                if len(got) == count:
                    break
        talker.join()
        assert got == [str(i) for i in range(count)]
        stats = sub.stats
        assert (stats.received, stats.delivered) == (count, count)
        if held is not None:
            held.append(ws.held_reads - direct)
            held.append(ws.paced_reads - paced)
        return ws.reads - reads, ws.coalesced - waited


async def test_a_steady_stream_is_read_in_batches_and_arrives_whole(
    server: SdkServer,
) -> None:
    count = 800
    held: list[int] = []
    reads, waited = await receive(server, count, hz=1000.0, window=0.004, held=held)
    # each waiting read took what arrived in up to 4 ms: about 4 frames a read
    assert waited > 0
    assert reads < count // 2, (reads, waited)
    # and most of them took the socket's bytes at once, without a round
    # through the event loop (asyncio: the paused socket; trio: trio's socket)
    assert 0 < held[0] <= waited, (held, waited)
    assert held[0] >= waited // 2, (held, waited)
    # most of those reads were taken where the loop ended the wait (asyncio:
    # the timer's callback; trio: the loop's shared timer), and the wait
    # after them started there: no task step for the reader
    assert held[1] >= waited // 2, (held, waited)


async def test_a_slow_stream_is_read_as_it_arrives(server: SdkServer) -> None:
    # 100 ms between messages, far slower than the 4 ms window: never steady
    # (a late thread wake-up may put two messages close together once or
    # twice; at 25 ms apart it did more often on a loaded machine)
    reads, waited = await receive(server, 20, hz=10.0, window=0.004)
    assert waited <= 2, (reads, waited)
    assert reads >= 18


async def test_no_read_waits_when_coalescing_is_off(server: SdkServer) -> None:
    held: list[int] = []
    _, waited = await receive(server, 400, hz=1000.0, window=0.0, held=held)
    assert waited == 0
    assert held == [0, 0]  # no wait: nothing read at the end of one


def test_the_window_is_bounded() -> None:
    assert rmb.ClientOptions().read_coalesce == 0.004
    assert rmb.ClientOptions(read_coalesce=0).read_coalesce == 0
    with pytest.raises(ValueError, match="read_coalesce"):
        rmb.ClientOptions(read_coalesce=-0.001)
    with pytest.raises(ValueError, match=r"at most 0\.1"):
        rmb.ClientOptions(read_coalesce=0.2)
    with pytest.raises(TypeError, match="read_coalesce"):
        rmb.ClientOptions(read_coalesce="2ms")  # type: ignore[arg-type]
