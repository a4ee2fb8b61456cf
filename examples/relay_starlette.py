"""Relay one robot topic to browsers over WebSocket, latest-only (Starlette + uvicorn).

One robot client serves the whole app (opened and closed by the app's lifespan).
Its subscription uses ``dispatch="latest"``, and a single slot holds the newest
message: every browser reads from that slot, so nothing queues per browser.

Each browser gets one message, then, each time it answers (any text frame, say
``"next"``, sent when it is ready for more), the newest message at that moment:
a slow browser skips what it missed (the ``seq`` numbers jump) instead of
falling behind, and at most one message per browser is ever in flight. Pushing
without waiting for that answer would leave stale messages in the socket
buffers, which latest-only delivery is meant to avoid.

    rmb demo --serve --port 8765 &
    python examples/relay_starlette.py ws://127.0.0.1:8765 /odom --port 8000
    # open http://127.0.0.1:8000/ (a page that shows the stream), or connect to
    # ws://127.0.0.1:8000/ws: {"seq": 1, "topic": "/odom", "receive_time_ns": ..., "data": {...}}
"""

from __future__ import annotations

import argparse
import json
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager

import anyio
import uvicorn
from starlette.applications import Starlette
from starlette.requests import Request
from starlette.responses import HTMLResponse
from starlette.routing import Route, WebSocketRoute
from starlette.websockets import WebSocket, WebSocketDisconnect

import ros_mobile_bridge as rmb

PAGE = """<!doctype html><title>rmb relay</title><pre id="out">connecting...</pre><script>
const ws = new WebSocket(`ws://${location.host}/ws`);
ws.onmessage = (e) => { document.getElementById("out").textContent = e.data; ws.send("next"); };
</script>"""


class Latest:
    """The newest message (its number and JSON text); a new one replaces the old."""

    def __init__(self) -> None:
        self.seq = 0
        self.text = ""
        self._changed = anyio.Event()

    def put(self, seq: int, text: str) -> None:
        self.seq, self.text = seq, text
        self._changed.set()
        self._changed = anyio.Event()

    async def newer_than(self, seq: int) -> tuple[int, str]:
        while self.seq <= seq:
            await self._changed.wait()
        return self.seq, self.text


async def pump(robot: rmb.Client, topic: str, latest: Latest) -> None:
    seq = 0
    async with robot.subscribe(topic, dispatch="latest") as sub:
        async for msg in sub:
            seq += 1
            record = {
                "seq": seq,
                "topic": msg.topic,
                "receive_time_ns": msg.receive_time_ns,
                "data": rmb.jsonable(msg.data),
            }
            latest.put(seq, json.dumps(record, allow_nan=False))


def create_app(robot_url: str, topic: str) -> Starlette:
    latest = Latest()

    @asynccontextmanager
    async def lifespan(app: Starlette) -> AsyncIterator[None]:
        async with rmb.connect(robot_url) as robot, anyio.create_task_group() as tg:
            tg.start_soon(pump, robot, topic, latest)
            yield
            tg.cancel_scope.cancel()
        # leaving connect() closed the robot client (zero Twist if it had driven)

    async def page(request: Request) -> HTMLResponse:
        return HTMLResponse(PAGE)

    async def relay(websocket: WebSocket) -> None:
        await websocket.accept()
        seq = 0
        try:
            while True:
                seq, text = await latest.newer_than(seq)
                await websocket.send_text(text)
                await websocket.receive_text()  # the browser asks for the next one
        except WebSocketDisconnect:
            pass  # this browser left; the others are not affected

    return Starlette(routes=[Route("/", page), WebSocketRoute("/ws", relay)], lifespan=lifespan)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("robot", help="robot URL, e.g. ws://127.0.0.1:8765")
    parser.add_argument("topic", nargs="?", default="/odom")
    parser.add_argument("--host", default="127.0.0.1")
    parser.add_argument("--port", type=int, default=8000)
    a = parser.parse_args()
    uvicorn.run(create_app(a.robot, a.topic), host=a.host, port=a.port, log_level="warning")
