"""Serves normally until the client advertises a topic to publish on, then
never reads the socket again (the client's writes back up, its pings go
unanswered) while keeping TCP open."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, bridge

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.client_advertised.wait()
        conn.stop_reading()
        await trio.sleep_forever()
