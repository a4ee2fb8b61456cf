"""The asyncio TCP stream (``transport/_asyncio_stream.py``) against real
sockets: order, EOF, a reset, closing, back-pressure both ways, on asyncio's
own loop and on uvloop. On trio the WebSocket keeps anyio's stream, which the
last test checks."""

from __future__ import annotations

import asyncio
import socket
import threading
import time
from collections.abc import Iterator

import anyio
import pytest

from _util import ASYNCIO_LOOPS, wait_until, wait_until_sync
from peers.scripted import Peer, scripted_server
from ros_mobile_bridge.transport import ConnectionLost, _asyncio_stream, connect_websocket
from ros_mobile_bridge.transport._asyncio_stream import ProtocolStream


class RawPeer:
    """A blocking TCP server in a thread: accepts one connection and runs
    ``script(conn)`` on it."""

    def __init__(self) -> None:
        self.listener = socket.create_server(("127.0.0.1", 0))
        self.port = self.listener.getsockname()[1]
        self.conn: socket.socket | None = None
        self.accepted = threading.Event()
        self.thread = threading.Thread(target=self._accept, daemon=True)
        self.thread.start()

    def _accept(self) -> None:
        self.conn, _ = self.listener.accept()
        self.accepted.set()

    def wait(self) -> socket.socket:
        assert self.accepted.wait(10)
        assert self.conn is not None
        return self.conn

    def close(self) -> None:
        if self.conn is not None:
            self.conn.close()
        self.listener.close()


@pytest.fixture
def peer() -> Iterator[RawPeer]:
    p = RawPeer()
    yield p
    p.close()


asyncio_only = pytest.mark.parametrize("anyio_backend", ASYNCIO_LOOPS)


async def recv_all(stream: ProtocolStream, n: int) -> bytes:
    got = b""
    while len(got) < n:
        got += await stream.receive()
    return got


@asyncio_only
async def test_bytes_arrive_in_order_both_ways(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    await stream.send(b"hello")
    assert await anyio.to_thread.run_sync(conn.recv, 5) == b"hello"
    data = bytes(range(256)) * 4096  # 1 MiB
    await anyio.to_thread.run_sync(conn.sendall, data)
    assert await recv_all(stream, len(data)) == data
    await stream.aclose()


@asyncio_only
async def test_receive_honours_max_bytes(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    await anyio.to_thread.run_sync(conn.sendall, b"abcdefgh")
    got = b""
    while len(got) < 8:
        chunk = await stream.receive(3)
        assert 1 <= len(chunk) <= 3
        got += chunk
    assert got == b"abcdefgh"
    await stream.aclose()


@asyncio_only
async def test_eof_is_end_of_stream_and_writes_still_go_out(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    await anyio.to_thread.run_sync(conn.sendall, b"last")
    await anyio.to_thread.run_sync(conn.shutdown, socket.SHUT_WR)
    assert await recv_all(stream, 4) == b"last"
    with pytest.raises(anyio.EndOfStream):
        await stream.receive()
    await stream.send(b"reply")  # half-closed: our side may still write
    assert await anyio.to_thread.run_sync(conn.recv, 5) == b"reply"
    await stream.aclose()


@asyncio_only
async def test_a_reset_is_a_broken_resource(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")
    conn.close()  # linger 0: RST
    peer.conn = None
    with pytest.raises((anyio.BrokenResourceError, anyio.EndOfStream)):
        with anyio.fail_after(5):
            while True:
                await stream.receive()
    with pytest.raises(anyio.BrokenResourceError):
        with anyio.fail_after(5):
            while True:  # the first write may still be accepted by the kernel
                await stream.send(b"x" * 65536)
    await stream.aclose()


@asyncio_only
async def test_after_aclose_everything_raises_closed(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    await anyio.to_thread.run_sync(peer.wait)
    await stream.aclose()
    await stream.aclose()  # twice is harmless
    with pytest.raises(anyio.ClosedResourceError):
        await stream.receive()
    with pytest.raises(anyio.ClosedResourceError):
        await stream.send(b"x")
    with pytest.raises(anyio.ClosedResourceError):
        await stream.send_eof()


@asyncio_only
async def test_a_waiting_receive_is_cancellable_and_loses_nothing(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    with anyio.move_on_after(0.05) as scope:
        await stream.receive()
    assert scope.cancelled_caught
    await anyio.to_thread.run_sync(conn.sendall, b"after")
    assert await recv_all(stream, 5) == b"after"
    await stream.aclose()


@asyncio_only
async def test_a_send_stuck_on_a_peer_that_does_not_read_raises_when_closed(
    peer: RawPeer,
) -> None:
    """The peer reads nothing: writes fill the kernel's buffers, then the
    transport's, then ``send`` waits. Closing the stream ends that wait with
    an error: the bytes were never written, so the send must not return."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    outcome: list[str] = []
    sent = 0

    async def writer() -> None:
        nonlocal sent
        try:
            while True:
                await stream.send(b"x" * 65536)
                sent += 1
        except anyio.ClosedResourceError:
            outcome.append("closed")

    async with anyio.create_task_group() as tg:
        tg.start_soon(writer)
        # the buffers are full, and the writer waits in send()
        await wait_until(lambda: stream._protocol.write_paused, 10, "the transport paused")
        await anyio.wait_all_tasks_blocked()
        before = sent
        await stream.aclose()
    assert outcome == ["closed"]
    assert sent == before  # the waiting send did not return


@asyncio_only
async def test_write_nowait_writes_until_the_transport_is_full_and_never_after_close(
    peer: RawPeer,
) -> None:
    """``write_nowait`` writes what needs no wait (received in order by the
    peer); with the transport over its high-water mark it writes nothing,
    and ``send`` is the way; after ``aclose`` it writes nothing either."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    assert stream.write_nowait(b"one ")
    assert stream.write_nowait(b"two")
    assert not stream.write_nowait(b"")  # an end of stream is send_eof's
    got = b""
    while len(got) < 7:
        got += await anyio.to_thread.run_sync(conn.recv, 64)
    assert got == b"one two"
    conn.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    chunk = b"x" * 65536
    written = 0
    with anyio.fail_after(10):
        while stream.write_nowait(chunk):  # the peer reads nothing now
            written += 1
            await anyio.sleep(0)
    assert written > 0
    assert stream._protocol.write_paused
    assert not stream.write_nowait(b"y")  # full: nothing written
    await stream.aclose()
    assert not stream.write_nowait(b"z")
    with pytest.raises(anyio.ClosedResourceError):
        await stream.send(b"z")


async def test_a_websocket_send_to_a_peer_that_does_not_read_fails_after_send_timeout() -> None:
    """Sends that need no wait are written at once (asyncio: without a
    cancel scope); once the peer stops reading and the buffers fill, a send
    waits, and past ``send_timeout`` the connection is failed with
    ``ConnectionLost`` (1011), never left half written; later sends raise
    at once."""
    stopped = anyio.Event()

    async def stop(peer: Peer) -> None:
        peer.stop_reading()
        stopped.set()
        await anyio.sleep(30)

    async with scripted_server(stop) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",))
        ws.send_timeout = 0.5
        await stopped.wait()
        big = b"x" * 262144
        sent = 0
        with anyio.fail_after(20), pytest.raises(ConnectionLost) as caught:
            while True:
                await ws.send(big)
                sent += 1
        assert sent > 0
        assert "did not complete within" in str(caught.value)
        with pytest.raises(ConnectionLost):
            await ws.send(b"after")
        await ws.aclose(timeout=0.5)


@asyncio_only
async def test_a_reader_that_falls_behind_pauses_the_socket(peer: RawPeer) -> None:
    """More than the high-water mark unread: reading from the socket pauses
    (the peer's writes back up in the kernel), and resumes once taken."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    total = 3 * _asyncio_stream._HIGH_WATER
    block = b"y" * (1 << 20)
    done = threading.Event()

    def send_all() -> None:
        for _ in range(total // len(block)):
            conn.sendall(block)
        done.set()

    thread = threading.Thread(target=send_all, daemon=True)
    thread.start()
    await wait_until(lambda: stream._protocol.read_paused, 10, what="reading to pause")
    assert stream._protocol.buffered <= _asyncio_stream._HIGH_WATER + (1 << 20)
    assert await recv_all(stream, total) == b"y" * total
    assert not stream._protocol.read_paused
    assert done.wait(10)
    await stream.aclose()


@asyncio_only
async def test_what_arrives_during_a_hold_is_read_in_one_go(peer: RawPeer) -> None:
    """``hold`` pauses reading: segments sent meanwhile wait in the kernel
    and come back as one chunk after it (one wake-up, not one each), read by
    the hold itself, which leaves reading paused for the next hold until
    ``receive`` has to wait."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)

    def send_three() -> None:
        for part in (b"one,", b"two,", b"three"):
            conn.sendall(part)
            time.sleep(0.02)

    async with anyio.create_task_group() as tg:
        tg.start_soon(anyio.to_thread.run_sync, send_three)
        await stream.hold(0.3)
        assert list(stream._protocol.chunks) == [b"one,two,three"]  # one read, after the wait
        assert stream._protocol.read_paused  # still paused: the next hold reads again
    assert stream.held_reads == 1
    assert await stream.receive() == b"one,two,three"
    await anyio.to_thread.run_sync(conn.sendall, b"four")
    assert await stream.receive() == b"four"  # it had to wait: reading resumed
    assert not stream._protocol.read_paused
    await stream.hold(0.01)  # nothing arrives: reading resumes after the wait
    assert not stream._protocol.read_paused and not stream._protocol.chunks
    assert stream.held_reads == 1
    await stream.aclose()


@asyncio_only
async def test_a_hold_that_meets_the_end_of_the_stream_resumes_reading(peer: RawPeer) -> None:
    """Bytes and then the peer's EOF during a hold: the hold reads the
    bytes; the next hold finds the end, resumes reading, and ``receive``
    reports the end (the transport saw it itself)."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)

    def send_late() -> None:
        wait_until_sync(lambda: stream._protocol.held, what="the hold")  # reading paused
        conn.sendall(b"last")

    async with anyio.create_task_group() as tg:
        tg.start_soon(anyio.to_thread.run_sync, send_late)
        await stream.hold(0.3)
    assert stream.held_reads == 1
    assert await stream.receive() == b"last"
    conn.shutdown(socket.SHUT_WR)
    await stream.hold(0.05)
    assert stream.held_reads == 1
    assert not stream._protocol.read_paused
    with anyio.fail_after(5), pytest.raises(anyio.EndOfStream):
        await stream.receive()
    await stream.aclose()


@asyncio_only
async def test_a_paced_hold_reads_in_its_timer_and_goes_on_while_reads_are_taken(
    peer: RawPeer,
) -> None:
    """With ``paced`` set, the hold's timer reads the paused socket and offers
    the read: a read taken whole with another wait asked for continues the
    hold from the callback (the waiting task is not resumed); a read taken
    in part ends the hold with the rest buffered, in order."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    offered: list[bytes] = []
    following = {b"keep1": b"keep2", b"keep2": b"xxrest"}

    def paced(data: bytes) -> tuple[int, float]:
        offered.append(data)
        if data in following:  # the peer sends the next part during the next wait
            conn.sendall(following[data])
            return len(data), 0.05  # all taken: wait again
        return 2, 0.05  # two bytes taken: the rest is the reader's

    stream.paced = paced

    def send_first() -> None:
        wait_until_sync(lambda: stream._protocol.held, what="the hold")  # reading paused
        conn.sendall(b"keep1")

    async with anyio.create_task_group() as tg:
        tg.start_soon(anyio.to_thread.run_sync, send_first)
        hold_started = time.monotonic()
        with anyio.fail_after(5):
            await stream.hold(0.05)
        held_for = time.monotonic() - hold_started
    # one hold: three timer reads, two of them taken whole (no task step)
    assert offered == [b"keep1", b"keep2", b"xxrest"]
    assert held_for >= 0.14, held_for  # the task slept through the first two reads
    assert (stream.paced_reads, stream.held_reads) == (2, 3)
    assert await stream.receive() == b"rest"
    # nothing arrives: the timer finds nothing, the hold ends and reading resumes
    await stream.hold(0.01)
    assert offered == [b"keep1", b"keep2", b"xxrest"]
    assert not stream._protocol.read_paused or not stream._protocol.held
    await anyio.to_thread.run_sync(conn.sendall, b"after")
    with anyio.fail_after(5):
        assert await recv_all(stream, 5) == b"after"
    await stream.aclose()


@asyncio_only
async def test_a_cancelled_hold_resumes_reading(peer: RawPeer) -> None:
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    with anyio.move_on_after(0.05) as scope:
        await stream.hold(10)
    assert scope.cancelled_caught
    assert not stream._protocol.read_paused
    await anyio.to_thread.run_sync(conn.sendall, b"after")
    assert await recv_all(stream, 5) == b"after"
    await stream.aclose()


async def test_the_websocket_uses_this_stream_only_on_asyncio(
    anyio_backend_name: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A plain ``ws://`` connection on asyncio goes through this stream; on
    trio through anyio's."""
    calls: list[str] = []
    real = _asyncio_stream.connect_tcp

    async def spy(host: str, port: int) -> ProtocolStream:
        calls.append(host)
        return await real(host, port)

    monkeypatch.setattr(_asyncio_stream, "connect_tcp", spy)

    async def until_closed(peer: Peer) -> None:
        await peer.drain()

    async with scripted_server(until_closed) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",))
        await ws.aclose(timeout=0.5)
    assert calls == (["127.0.0.1"] if anyio_backend_name == "asyncio" else [])


@asyncio_only
async def test_receive_into_takes_buffered_bytes_first_then_reads_straight_in(
    peer: RawPeer,
) -> None:
    """Bytes already buffered are copied in (what does not fit stays
    buffered, in order); with nothing buffered the socket's next read lands
    in the caller's buffer; the end of the stream raises ``EndOfStream``."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    conn = await anyio.to_thread.run_sync(peer.wait)
    await anyio.to_thread.run_sync(conn.sendall, b"abcdefgh")
    await wait_until(lambda: stream.has_data, 10, what="the bytes to be buffered")
    target = bytearray(5)
    assert await stream.receive_into(memoryview(target)) == 5
    assert target == b"abcde"
    assert await stream.receive_into(memoryview(target)) == 3  # the rest of that read
    assert target[:3] == b"fgh"
    assert not stream.has_data
    block = bytes(range(256)) * 1024
    big = bytearray(len(block))
    view = memoryview(big)
    sender = threading.Thread(target=conn.sendall, args=(block,))
    sender.start()
    filled = 0
    with anyio.fail_after(10):
        while filled < len(block):
            filled += await stream.receive_into(view[filled:])
    sender.join()
    assert big == block
    assert not stream.has_data  # nothing went through the buffer
    conn.shutdown(socket.SHUT_WR)
    with pytest.raises(anyio.EndOfStream), anyio.fail_after(10):
        await stream.receive_into(view)
    await stream.aclose()


@asyncio_only
async def test_a_read_that_landed_before_a_cancellation_is_counted_next_time(
    peer: RawPeer,
) -> None:
    """``receive_into`` cancelled after the socket's read landed in its
    buffer (the loop read it, and buffered a later read, before the task
    resumed): the next call with the same view returns that count, the one
    after it the buffered bytes, so no byte is lost or overwritten."""
    stream = await _asyncio_stream.connect_tcp("127.0.0.1", peer.port)
    await anyio.to_thread.run_sync(peer.wait)
    target = bytearray(8)
    view = memoryview(target)
    outcome: list[str] = []

    async def reader() -> None:
        try:
            await stream.receive_into(view)
        except asyncio.CancelledError:
            outcome.append("cancelled")
            raise

    task = asyncio.get_running_loop().create_task(reader())
    await wait_until(lambda: stream._protocol.target is not None, 10, what="the reader's buffer")
    # what the event loop does on a read, then the cancellation before the
    # reader resumes (asyncio's own: it cancels a task whose wait is over)
    p = stream._protocol
    landed = p.get_buffer(-1)
    landed[:3] = b"xyz"
    p.buffer_updated(3)
    later = p.get_buffer(-1)  # and a later read, buffered
    later[:4] = b"more"
    p.buffer_updated(4)
    task.cancel()
    with pytest.raises(asyncio.CancelledError):
        await task
    assert outcome == ["cancelled"]
    assert p.target is None
    with anyio.fail_after(5):  # (nothing more comes from the peer)
        assert await stream.receive_into(view) == 3
        assert target[:3] == b"xyz"
        assert await stream.receive_into(view[3:]) == 4
    assert target[:7] == b"xyzmore"
    await stream.aclose()
