"""Foxglove: on ``/blob``'s subscription, ``hz`` (default 2000) messages
a second of ``size`` bytes (default 10,000) for ``seconds`` (default 10),
in bursts every 10 ms; what the client publishes meanwhile is recorded.
The number sent is recorded as ``flood_done``."""

from __future__ import annotations

import time

import trio

from peers.hostile_server import Conn, Foxglove, cdr_bytes

PROTOCOL = "foxglove"


async def flood(conn: Conn, b: Foxglove) -> None:
    await b.subscribed("/blob")
    hz = float(conn.arg("hz", "2000"))
    payload = cdr_bytes(bytes(int(conn.arg("size", "10000")) - 8))
    seconds = float(conn.arg("seconds", "10"))
    start = time.monotonic()
    sent = 0
    conn.record("flood_start")
    while (now := time.monotonic() - start) < seconds:
        while sent < now * hz:
            await b.send_payload("/blob", payload)
            sent += 1
        await trio.sleep(0.01)
    conn.record("flood_done", sent=sent, seconds=time.monotonic() - start)


async def run(conn: Conn) -> None:
    b = Foxglove(conn, {"/blob": "hostile_msgs/msg/Blob"})
    await b.greet()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(flood, conn, b)
        await b.serve()
        nursery.cancel_scope.cancel()
