"""Foxglove: ``/big`` whose ros2msg schema has ``fields`` (default 40,000)
``uint8`` fields, and ``/chatter``; both stream while subscribed."""

from __future__ import annotations

import trio

from peers.hostile_server import Conn, Foxglove, stream_strings

PROTOCOL = "foxglove"


async def stream_big(b: Foxglove, fields: int) -> None:
    payload = b"\x00\x01\x00\x00" + bytes(fields)
    while True:
        if b.is_subscribed("/big"):
            await b.send_payload("/big", payload)
        await trio.sleep(0.2)


async def run(conn: Conn) -> None:
    fields = int(conn.arg("fields", "40000"))
    b = Foxglove(conn, {"/chatter": "std_msgs/msg/String"})
    await b.greet()
    schema = "\n".join(f"uint8 f{i}" for i in range(fields))
    await b.advertise([b.channel("/big", "hostile_msgs/msg/Big", schema)])
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        nursery.start_soon(stream_big, b, fields)
        await stream_strings(b, "/chatter")
