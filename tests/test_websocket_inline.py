"""Whole data messages taken where they are read (``WebSocket.handle_inline``,
asyncio's plain TCP stream): the messages the handler takes and those the
reader gets are, together, every message in the order sent, whatever the
reads are cut into and whatever control frames come between; a handler that
refuses or raises leaves the message to the reader. On both loops (asyncio
in the read callback, trio right after the reader's read)."""

from __future__ import annotations

import struct

import anyio
import pytest

from peers.hostile_server import frame
from peers.scripted import Peer, scripted_server
from ros_mobile_bridge.transport import ConnectionLost, connect_websocket


def messages(count: int, *, plain: bool) -> list[tuple[bool, bytes]]:
    """Text and binary, small, 16-bit-length and (unless ``plain``) one with
    a 64-bit length and some the handler refuses (``refuse`` in them)."""
    out: list[tuple[bool, bytes]] = []
    for i in range(count):
        size = 70_000 if i == 10 and not plain else (3, 200, 1000, 0)[i % 4]
        refused = i % 5 == 3 and not plain
        body = (b"refuse" if refused else b"take") + str(i).encode().rjust(6, b"0")
        out.append((i % 3 == 0, (body * (size // len(body) + 1))[: max(size, len(body))]))
    return out


async def pongs_until_close(peer: Peer) -> list[bytes]:
    """After the server sent its close: the pongs the client answers with,
    read until its close reply."""
    pongs: list[bytes] = []
    while peer.proto.close_rcvd is None:
        peer.proto.receive_data(await peer.stream.receive())
        for event in peer.proto.events_received():
            if getattr(event, "opcode", None) is not None and event.opcode.name == "PONG":
                pongs.append(bytes(event.data))
    return pongs


async def run_case(chunk: int, *, raising: bool = False) -> None:
    sent = messages(40, plain=raising)
    wire = b""
    for i, (text, data) in enumerate(sent):
        wire += frame(0x1 if text else 0x2, data)
        if i % 7 == 6 and not raising:
            wire += frame(0x9, b"p%d" % i)  # a ping between messages
    got: list[tuple[str, bool, bytes]] = []
    pongs: list[bytes] = []
    done = anyio.Event()

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"  # the client's reader waits from then on
        for start in range(0, len(wire), chunk):
            await peer.send_raw(wire[start : start + chunk])
            await anyio.sleep(0)
        await peer.send_raw(frame(0x8, struct.pack("!H", 1000)))
        # the pongs the client answered with, then its close reply
        pongs.extend(await pongs_until_close(peer))
        await done.wait()

    def handler(text: bool, data: bytes, start: int, stop: int) -> bool:
        body = data[start:stop]
        if b"refuse" in body:
            return False
        if raising and b"000013" in body:
            raise RuntimeError("a bug in the handler")
        got.append(("inline", text, body))
        return True

    async with scripted_server(script) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        ws.handle_inline(handler)
        await ws.send("go")
        with pytest.raises(ConnectionLost):
            with anyio.fail_after(20):
                while True:
                    text, data = await ws.receive_raw()
                    got.append(("reader", text, bytes(data)))
        done.set()
        await ws.aclose(timeout=0.5)
    assert [(text, data) for _, text, data in got] == sent
    inline = [data for how, _, data in got if how == "inline"]
    assert ws.inline_messages == len(inline)
    if chunk > len(wire):  # one write: its first messages start a read
        assert inline
    if raising:  # taken up to the raise; then the reader got all the rest
        assert [how for how, _, _ in got] == ["inline"] * 13 + ["reader"] * 27
    else:
        assert all(b"refuse" not in data for data in inline)
    assert sorted(pongs) == sorted(
        b"p%d" % i for i in range(len(sent)) if i % 7 == 6 and not raising
    )


@pytest.mark.parametrize("chunk", [7, 100, 1 << 20])
async def test_inline_and_reader_together_keep_every_message_in_order(chunk: int) -> None:
    await run_case(chunk)


async def test_a_handler_that_raises_is_removed_and_the_reader_takes_over() -> None:
    await run_case(1 << 20, raising=True)


async def test_a_reader_waiting_when_the_keepalive_closes_the_socket_gets_connection_lost() -> None:
    # the peer never reads, so never answers a ping: the keep-alive closes the
    # socket while the reader waits on it (on trio, in trio's readiness wait)
    async def silent(peer: Peer) -> None:
        await anyio.sleep(30)

    async with scripted_server(silent) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        ws.handle_inline(lambda text, data, start, stop: True)
        with anyio.fail_after(10):
            async with anyio.create_task_group() as tg:
                tg.start_soon(ws.keepalive, 0.05, 0.1)
                with pytest.raises(ConnectionLost, match="keep-alive"):
                    await ws.receive_raw()
        await ws.aclose(timeout=0.5)
    assert ws.closed
    assert ws.messages_received == 0


async def test_a_steady_stream_taken_at_the_end_of_each_wait_keeps_its_order(
    anyio_backend_name: str,
) -> None:
    """Read coalescing on, a steady stream of small messages with pings, a
    refused message now and then, and a close at the end: on asyncio most
    reads at the end of a wait are taken in the timer's callback (the
    reader task not resumed); a ping, a refused message or the close in
    such a read goes to the reader with everything after it. Every message
    arrives once, in order, every ping is answered, and the close ends the
    reader."""
    count = 300
    sent = [
        (False, (b"refuse" if i % 60 == 59 else b"take") + str(i).encode()) for i in range(count)
    ]
    pongs: list[bytes] = []
    done = anyio.Event()

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"
        for i, (_, data) in enumerate(sent):
            wire = frame(0x2, data)
            if i % 50 == 49:
                wire += frame(0x9, b"p%d" % i)
            await peer.send_raw(wire)
            await anyio.sleep(0.001)  # about 1 kHz: the client's reads coalesce
        await peer.send_raw(frame(0x8, struct.pack("!H", 1000)))
        pongs.extend(await pongs_until_close(peer))
        await done.wait()

    got: list[tuple[str, bytes]] = []

    def handler(text: bool, data: bytes, start: int, stop: int) -> bool:
        body = data[start:stop]
        if body.startswith(b"refuse"):
            return False
        got.append(("inline", body))
        return True

    async with scripted_server(script) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        ws.read_coalesce = 0.004
        ws.handle_inline(handler)
        await ws.send("go")
        with pytest.raises(ConnectionLost), anyio.fail_after(20):
            while True:
                _, data = await ws.receive_raw()
                got.append(("reader", bytes(data)))
        done.set()
        await ws.aclose(timeout=0.5)
    assert [data for _, data in got] == [data for _, data in sent]
    assert all(how == "reader" for how, data in got if data.startswith(b"refuse"))
    assert sorted(pongs) == sorted(b"p%d" % i for i in range(count) if i % 50 == 49)
    assert ws.coalesced > 0
    if anyio_backend_name == "asyncio":
        assert ws.paced_reads > ws.coalesced // 4, (ws.paced_reads, ws.coalesced)
    else:
        assert ws.paced_reads == 0
