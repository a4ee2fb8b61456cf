"""Large data frames (64 KiB and more: camera images) over a real socket, on
both loops: whatever the reads are cut into, each arrives whole, as one
``bytes`` of its size, in order with the small frames and control frames
around it. On a plain TCP socket a large frame's rest is read straight into
a buffer the connection keeps (``WebSocket.direct_frames`` counts them),
at most ``_DIRECT_MAX`` bytes (a larger frame is gathered chunk by chunk, and
the kept buffer never grows past the bound); the end of the stream or a
cancelled read in the middle of such a frame loses nothing it must not."""

from __future__ import annotations

import gc
import os
import struct
import tracemalloc
from collections.abc import Iterator

import anyio
import numpy as np
import pytest

import ros_mobile_bridge as rmb
from _util import wait_until
from peers.foxglove_sdk import SdkServer, image_msg
from peers.hostile_server import frame
from peers.scripted import Peer, scripted_server
from ros_mobile_bridge.transport import ConnectionLost, _ws_frames, connect_websocket

IMAGE = 640 * 480 * 3 + 52


def on_trio() -> bool:
    import sniffio

    return sniffio.current_async_library() == "trio"


@pytest.fixture
def small_bound() -> Iterator[int]:
    """``_DIRECT_MAX`` lowered to 300,000 bytes, so a 500 KB frame is over it."""
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(_ws_frames, "_DIRECT_MAX", 300_000)
        yield 300_000


@pytest.mark.parametrize("chunk", [4096, 100_003, 1 << 21])
async def test_large_frames_arrive_whole_as_bytes_in_order(chunk: int, small_bound: int) -> None:
    sent: list[tuple[bool, bytes]] = [
        (True, b"hello"),
        (False, os.urandom(IMAGE)),  # over 64 KiB and the bound: chunk by chunk
        (False, os.urandom(200_000)),  # under the bound: read straight in (trio)
        (True, b"x" * 70_000),  # a large text message
        (False, b"\x82\x02ab" * 30_000),  # bytes that look like small frames
        (False, os.urandom(100)),
        (False, os.urandom(250_000)),
    ]
    wire = b""
    for i, (text, data) in enumerate(sent):
        wire += frame(0x1 if text else 0x2, data)
        if i == 2:
            wire += frame(0x9, b"ping")
    pongs: list[bytes] = []

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"
        for start in range(0, len(wire), chunk):
            await peer.send_raw(wire[start : start + chunk])
            await anyio.sleep(0)
        await peer.send_raw(frame(0x8, struct.pack("!H", 1000)))
        while peer.proto.close_rcvd is None:
            peer.proto.receive_data(await peer.stream.receive())
            for event in peer.proto.events_received():
                if getattr(event, "opcode", None) is not None and event.opcode.name == "PONG":
                    pongs.append(bytes(event.data))

    got: list[tuple[bool, bytes | bytearray]] = []
    async with scripted_server(script) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        # the inline handler takes every whole small frame a read starts with
        ws.handle_inline(lambda text, data, a, b: got.append((text, bytes(data[a:b]))) is None)
        await ws.send("go")
        with pytest.raises(ConnectionLost), anyio.fail_after(20):
            while True:
                got.append(await ws.receive_raw())
        kept = len(ws._parser._direct_buf)  # the connection's kept buffer, until closed
        await ws.aclose(timeout=0.5)
    assert len(ws._parser._direct_buf) == 0  # freed by the close
    assert got == sent
    assert [type(data) for _, data in got] == [bytes] * len(sent)
    assert pongs == [b"ping"]
    under = sum(1 for _, data in sent if 64 * 1024 <= len(data) <= small_bound)
    if on_trio():
        # trio reads at most 64 KiB at a time: every large frame arrives in
        # pieces, and each one under the bound is read straight in
        assert ws.direct_frames == under == 4
        assert 250_000 <= kept <= small_bound
    else:  # asyncio reads up to 256 KiB: a frame may come whole in one read
        assert ws.direct_frames <= under
        assert kept <= small_bound


async def test_the_end_of_the_stream_inside_a_large_frame_ends_the_connection() -> None:
    first = os.urandom(1000)

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"
        large = frame(0x2, os.urandom(IMAGE))
        await peer.send_raw(frame(0x2, first) + large[: IMAGE // 2])
        await anyio.sleep(0.05)
        await peer.send_raw(large[IMAGE // 2 : -1000])
        await peer.stream.send_eof()  # the TCP stream ends, the frame never will
        await anyio.sleep(1)

    async with scripted_server(script) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        await ws.send("go")
        with anyio.fail_after(10):
            assert await ws.receive_raw() == (False, first)
            with pytest.raises(ConnectionLost, match="closed by peer"):
                await ws.receive_raw()
        assert ws.closed
        await ws.aclose(timeout=0.5)


async def test_a_lost_connection_frees_its_large_frame_buffer_once_closed() -> None:
    """The peer dies inside a large frame (a robot's server killed while it
    sends an image): once the connection is closed, the buffer it kept for
    large frames is freed at once, although the caller keeps the
    ``ConnectionLost`` (as ``client.last_error`` does) and the cyclic
    garbage collector does not run (the reason's traceback held the
    connection's frames, and through them the connection: a cycle, kept
    until the collector's next full pass, one such buffer per reconnection)."""

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"
        await peer.send_raw(frame(0x2, os.urandom(IMAGE))[: IMAGE // 2])
        await peer.stream.send_eof()

    collecting = gc.isenabled()
    gc.disable()
    tracemalloc.start()
    try:
        async with scripted_server(script) as url:
            ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
            before = tracemalloc.get_traced_memory()[0]
            await ws.send("go")
            kept: ConnectionLost | None = None
            with anyio.fail_after(10):
                try:
                    await ws.receive_raw()
                except ConnectionLost as exc:
                    kept = exc
            assert kept is not None
            assert tracemalloc.get_traced_memory()[0] - before > IMAGE // 2  # its buffer
            await ws.aclose(timeout=0.5)
            del ws
        held = tracemalloc.get_traced_memory()[0] - before
        assert held < IMAGE // 4, f"{held} bytes still held after the close"
        assert "closed by peer" in str(kept)
    finally:
        tracemalloc.stop()
        if collecting:
            gc.enable()


async def test_a_read_cancelled_inside_a_large_frame_loses_nothing() -> None:
    payload = os.urandom(IMAGE)
    wire = frame(0x2, payload) + frame(0x1, b"after")

    async def script(peer: Peer) -> None:
        assert await peer.recv() == "go"
        await peer.send_raw(wire[:300_000])
        assert await peer.recv() == "more"
        await peer.send_raw(wire[300_000:])
        await anyio.sleep(1)

    async with scripted_server(script) as url:
        ws = await connect_websocket(url, subprotocols=("foxglove.sdk.v1.1",), max_size=None)
        await ws.send("go")
        with anyio.move_on_after(0.3) as scope:
            await ws.receive_raw()  # waits inside the frame until cancelled
        assert scope.cancelled_caught
        await ws.send("more")
        with anyio.fail_after(10):
            assert await ws.receive_raw() == (False, payload)
            assert await ws.receive_raw() == (True, b"after")
        assert ws.direct_frames == 1
        await ws.aclose(timeout=0.5)


async def test_camera_images_arrive_whole_and_read_only(server: SdkServer) -> None:
    """Images from the official Foxglove SDK server: every one arrives, its
    pixels intact, as a read-only numpy array (the bytes it views); each
    was read straight into the connection's kept buffer."""
    cam = server.channel("/camera", "sensor_msgs/msg/Image")
    count = 12
    images = [np.full(640 * 480 * 3, i, dtype=np.uint8) for i in range(count)]
    for i, pixels in enumerate(images):
        pixels[i * 1000 : i * 1000 + 4] = (0x82, 0x02, 0x81, 0x05)
    options = rmb.ClientOptions(zero_twist_on_exit=False, keepalive_interval=0)
    async with rmb.connect(server.url, options=options) as robot:
        async with robot.subscribe("/camera", buffer=count, adaptive=False) as sub:
            await wait_until(lambda: "/camera" in server.subscribed(), 10, what="the subscribe")
            for pixels in images:
                cam.log(image_msg(pixels=pixels, stamp=(1, 2), frame_id="cam"))
            got = []
            with anyio.fail_after(20):
                async for msg in sub:
                    got.append(msg.data.data)
                    if len(got) == count:
                        break
            ws = robot._conn.adapter._ws  # type: ignore[attr-defined]
            assert ws.direct_frames == count  # larger than any one read
    assert all(np.array_equal(a, b) for a, b in zip(got, images, strict=True))
    assert not any(a.flags.writeable for a in got)
