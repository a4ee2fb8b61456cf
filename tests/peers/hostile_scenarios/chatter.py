"""A well-behaved server: ``/chatter`` (std_msgs/msg/String) ``"0"``,
``"1"``, ... at ``hz`` (default 20) while subscribed."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, bridge, stream_strings

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = bridge(conn, conn.arg("protocol", PROTOCOL))
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(stream_strings, b, "/chatter", float(conn.arg("hz", "20")))
        await b.serve()
        nursery.cancel_scope.cancel()
