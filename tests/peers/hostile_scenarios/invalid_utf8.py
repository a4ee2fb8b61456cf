"""On ``/chatter``'s subscription: a text frame whose payload is not
UTF-8 (hand-built, wsproto would refuse it), then ``"after"``, then the
usual stream."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, bridge, stream_strings

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.subscribed("/chatter")
        await conn.send_frame(0x1, b'{"op":"\xff\xfe\xc3\x28"}')
        conn.record("sent_invalid_utf8")
        await b.send_string("/chatter", "after")
        await stream_strings(b, "/chatter")
