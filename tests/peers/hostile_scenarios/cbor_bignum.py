"""rosbridge: on ``/chatter``'s subscription, three CBOR ``status`` frames
carrying a 20,000-bit integer as ``msg``, ``level`` and ``id``, then
``"after"`` and the usual stream."""

from __future__ import annotations

import cbor2
import trio

from peers.hostile_server import Conn, bridge, stream_strings

PROTOCOL = "rosbridge"
BIG = 1 << 20000


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.subscribed("/chatter")
        for frame in (
            {"op": "status", "level": "error", "msg": BIG},
            {"op": "status", "level": BIG, "msg": "x"},
            {"op": "status", "level": "error", "msg": "x", "id": BIG},
        ):
            await conn.send(cbor2.dumps(frame))
        conn.record("sent_bignums")
        await b.send_string("/chatter", "after")
        await stream_strings(b, "/chatter")
