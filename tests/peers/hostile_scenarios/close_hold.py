"""On ``/chatter``'s subscription (after one message): a Close frame
(1011 "bridge crashed"), then nothing: the socket is never read again and
TCP stays open (the client's Close reply is never seen)."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, bridge, close_frame

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.subscribed("/chatter")
        await b.send_string("/chatter", "before")
        await trio.sleep(float(conn.arg("delay", "0.3")))
        conn.stop_reading()
        await conn.send_raw(close_frame(1011, "bridge crashed"))
        conn.record("sent_close")
        await trio.sleep_forever()
