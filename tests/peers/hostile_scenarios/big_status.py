"""On ``/chatter``'s subscription: one status (error level) whose text is
``size`` characters (default 50 MB), then the usual stream."""

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
        await b.send_status("bridge says: " + "x" * int(conn.arg("size", str(50_000_000))))
        conn.record("sent_status")
        await stream_strings(b, "/chatter")
