"""Foxglove: on ``/blob``'s subscription (``uint8[] data``), one message
data frame of ``size`` bytes in all (default 256 KiB) sent as a first
frame and continuation frames of one byte each, then a small ``/blob``
message (``b"end"``). The payload is ``bytes(i % 251)``."""

from __future__ import annotations

import struct

import trio

from peers.hostile_server import Conn, Foxglove, cdr_bytes, one_byte_fragments

PROTOCOL = "foxglove"
HEADER = 1 + 4 + 8 + 4 + 4  # opcode, subscription, log time; CDR header, length


def pattern(n: int) -> bytes:
    return bytes(i % 251 for i in range(n))


async def run(conn: Conn) -> None:
    b = Foxglove(conn, {"/blob": "hostile_msgs/msg/Blob"})
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(b.serve)
        await b.subscribed("/blob")
        sid = b.subs[b.channels["/blob"]]
        size = int(conn.arg("size", str(256 * 1024)))
        message = b"\x01" + struct.pack("<IQ", sid, 1) + cdr_bytes(pattern(size - HEADER))
        assert len(message) == size
        await conn.send_raw(one_byte_fragments(0x2, message))
        conn.record("sent_fragments", size=size)
        await b.send_payload("/blob", cdr_bytes(b"end"))
        await trio.sleep_forever()
