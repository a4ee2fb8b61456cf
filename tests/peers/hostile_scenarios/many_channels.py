"""Foxglove: after the greeting (``/chatter``), one advertise of
``channels`` (default 100,000) String channels ``/c/<n>``; after ``delay``
seconds (default 1) a small advertise of ``/early`` (refused by a client
already at its channel limit); then the flood is unadvertised in one
message and ``/late`` advertised (a client must now accept it)."""

from __future__ import annotations

import json

import trio

from peers.hostile_server import Conn, Foxglove, stream_strings

PROTOCOL = "foxglove"


async def run(conn: Conn) -> None:
    b = Foxglove(conn)
    await b.greet()
    count = int(conn.arg("channels", "100000"))
    flood = [b.channel(f"/c/{n}", "std_msgs/msg/String") for n in range(count)]
    await b.advertise(flood)
    conn.record("sent_channels", count=count)
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        nursery.start_soon(stream_strings, b, "/chatter")
        await trio.sleep(float(conn.arg("delay", "1")))
        await b.advertise([b.channel("/early", "std_msgs/msg/String")])
        conn.record("sent_early")
        await trio.sleep(float(conn.arg("delay", "1")))
        ids = [c["id"] for c in flood]
        await conn.send(json.dumps({"op": "unadvertise", "channelIds": ids}))
        await b.advertise([b.channel("/late", "std_msgs/msg/String")])
        conn.record("sent_late")
