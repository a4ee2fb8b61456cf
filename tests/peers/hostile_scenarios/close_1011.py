"""On ``/chatter``'s subscription (after one message): a normal closing
handshake with 1011 "bridge crashed"."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, bridge

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.subscribed("/chatter")
        await b.send_string("/chatter", "before")
        await trio.sleep(float(conn.arg("delay", "0.3")))
        conn.record("closing")
        await conn.ws.aclose(1011, "bridge crashed")
        nursery.cancel_scope.cancel()
