"""rosbridge: discovery works (``/set_flag``, action server
``/fibonacci``), ``/chatter`` streams; every other service call and every
action goal is recorded (``call`` / ``goal``) and never answered."""

from __future__ import annotations

from typing import Any

import trio

from peers.hostile_server import Conn, Rosbridge, stream_strings

PROTOCOL = "rosbridge"


async def run(conn: Conn) -> None:
    b = Rosbridge(conn)

    async def on_call(obj: dict[str, Any]) -> None:
        conn.record("call", service=obj.get("service"))

    async def on_goal(obj: dict[str, Any]) -> None:
        conn.record("goal", action=obj.get("action"))

    b.on_call = on_call
    b.on_goal = on_goal
    async with trio.open_nursery() as nursery:
        nursery.start_soon(stream_strings, b, "/chatter")
        await b.serve()
        nursery.cancel_scope.cancel()
