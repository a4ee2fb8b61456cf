"""A hostile WebSocket server for the fault tests, on trio + trio-websocket
(wsproto): a different WebSocket implementation from the client's
(websockets), run in its own process by :mod:`peers.hostile`.

    python -m peers.hostile_server SCENARIO [--port N] [--log FILE] [--arg K=V ...]

It prints ``PORT <n>`` on stdout once listening, serves every connection
with the scenario module ``peers.hostile_scenarios.<SCENARIO>`` (a module
with ``PROTOCOL = "foxglove" | "rosbridge"`` and ``async def run(conn)``),
and appends one JSON object per line to the log file: what each client sent
and what the scenario chose to record.

A scenario gets a :class:`Conn`: the trio-websocket connection (``conn.ws``)
plus raw powers wsproto does not offer: :meth:`Conn.send_frame` writes a
hand-built frame (any opcode, FIN bit and payload, even invalid UTF-8 in a
text frame) straight onto the TCP stream, :meth:`Conn.stop_reading` stops
reading the socket (the client's writes back up and its pings go
unanswered, and a Close it sends is never seen), and :class:`Foxglove` /
:class:`Rosbridge` speak just enough of each protocol for the client to
connect, discover and subscribe."""

from __future__ import annotations

import argparse
import importlib
import json
import struct
import sys
import time
import traceback
from collections.abc import Awaitable, Callable
from typing import Any

import trio
import trio_websocket
from trio_websocket import ConnectionClosed, WebSocketConnection, WebSocketRequest

FOXGLOVE_SUBPROTOCOLS = ("foxglove.sdk.v1", "foxglove.websocket.v1")

_LOG: Any = None
_CONN_IDS = iter(range(1, 1 << 30))


def record(event: str, **fields: Any) -> None:
    """One JSON line in the log file (flushed: the test reads it live)."""
    if _LOG is not None:
        _LOG.write(json.dumps({"t": time.time(), "event": event, **fields}) + "\n")
        _LOG.flush()


# -- raw frames ---------------------------------------------------------------------


def frame(opcode: int, payload: bytes, *, fin: bool = True) -> bytes:
    """One unmasked (server-to-client) WebSocket frame, built by hand."""
    head = bytes([(0x80 if fin else 0) | opcode])
    n = len(payload)
    if n < 126:
        head += bytes([n])
    elif n < 1 << 16:
        head += bytes([126]) + struct.pack(">H", n)
    else:
        head += bytes([127]) + struct.pack(">Q", n)
    return head + payload


def close_frame(code: int, reason: str) -> bytes:
    return frame(0x8, struct.pack(">H", code) + reason.encode())


def one_byte_fragments(opcode: int, payload: bytes) -> bytes:
    """``payload`` as a first frame and continuation frames of one byte each."""
    parts = [
        frame(opcode if i == 0 else 0x0, payload[i : i + 1], fin=i == len(payload) - 1)
        for i in range(len(payload))
    ]
    return b"".join(parts)


class GatedStream(trio.abc.HalfCloseableStream):
    """The TCP stream under one trio-websocket connection: writes are
    serialized (the connection's and raw ones), and reading can be stopped.
    A chunk already being read when reading stops is held back, not handed
    to wsproto."""

    def __init__(self, inner: trio.SocketStream) -> None:
        self.inner = inner
        self._lock = trio.Lock()
        self._reading = True

    def stop_reading(self) -> None:
        self._reading = False

    async def _gate(self) -> None:
        if not self._reading:
            await trio.sleep_forever()

    async def receive_some(self, max_bytes: int | None = None) -> bytes:
        await self._gate()
        data = await self.inner.receive_some(max_bytes)
        await self._gate()
        return bytes(data)

    async def send_all(self, data: bytes | bytearray | memoryview) -> None:
        async with self._lock:
            await self.inner.send_all(data)

    async def wait_send_all_might_not_block(self) -> None:
        await self.inner.wait_send_all_might_not_block()

    async def send_eof(self) -> None:
        await self.inner.send_eof()

    async def aclose(self) -> None:
        await self.inner.aclose()

    def __repr__(self) -> str:
        # trio-websocket names a stream that is no trio.SocketStream by its
        # repr (``request.remote``): the key the handler finds it by.
        return f"GatedStream({id(self)})"


class GatedListener(trio.abc.Listener[GatedStream]):
    def __init__(self, inner: trio.SocketListener, streams: dict[str, GatedStream]) -> None:
        self.inner = inner
        self.streams = streams

    async def accept(self) -> GatedStream:
        stream = GatedStream(await self.inner.accept())
        self.streams[repr(stream)] = stream
        return stream

    async def aclose(self) -> None:
        await self.inner.aclose()


class Conn:
    """One accepted connection, as a scenario sees it."""

    def __init__(self, ws: WebSocketConnection, stream: GatedStream, args: dict[str, str]) -> None:
        self.ws = ws
        self.stream = stream
        self.args = args
        self.id = next(_CONN_IDS)

    def arg(self, name: str, default: str) -> str:
        return self.args.get(name, default)

    def record(self, event: str, **fields: Any) -> None:
        record(event, conn=self.id, **fields)

    async def send(self, message: str | bytes) -> None:
        await self.ws.send_message(message)

    async def send_raw(self, data: bytes) -> None:
        """Bytes straight onto the TCP stream, after whatever the
        connection already wrote (writes are serialized)."""
        await self.stream.send_all(data)

    async def send_frame(self, opcode: int, payload: bytes, *, fin: bool = True) -> None:
        await self.send_raw(frame(opcode, payload, fin=fin))

    def stop_reading(self) -> None:
        """Read nothing more from the client (see :class:`GatedStream`)."""
        self.record("stop_reading")
        self.stream.stop_reading()

    async def receive(self) -> str | bytes:
        """The client's next message, recorded in the log."""
        message = await self.ws.get_message()
        if isinstance(message, str):
            try:
                op = json.loads(message).get("op")
            except (ValueError, AttributeError):
                op = None
            self.record("recv", kind="text", op=op, text=message[:2000], len=len(message))
        else:
            self.record(
                "recv",
                kind="binary",
                opcode=message[:1].hex(),
                head=message[:32].hex(),
                len=len(message),
            )
        return message


# -- protocols ----------------------------------------------------------------------


def cdr_string(text: str) -> bytes:
    """A ``std_msgs/msg/String`` in CDR (little endian)."""
    raw = text.encode() + b"\x00"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(raw)) + raw


def cdr_bytes(data: bytes) -> bytes:
    """A ``uint8[] data`` message in CDR (little endian)."""
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(data)) + data


SCHEMAS = {
    "std_msgs/msg/String": "string data",
    "hostile_msgs/msg/Blob": "uint8[] data",
    "geometry_msgs/msg/Twist": "geometry_msgs/Vector3 linear\ngeometry_msgs/Vector3 angular\n"
    "================================================================================\n"
    "MSG: geometry_msgs/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n",
}


class Foxglove:
    """Just enough of a Foxglove server: ``serverInfo``, ``advertise``
    (ros2msg schemas, CDR), ``subscribe`` / ``unsubscribe``, and recording
    what the client publishes (``clientPublish``)."""

    def __init__(self, conn: Conn, topics: dict[str, str] | None = None) -> None:
        self.conn = conn
        self.channels: dict[str, int] = {}
        self.subs: dict[int, int] = {}  # channel id -> subscription id
        self.client_channels: dict[int, str] = {}
        self._subscribed: dict[int, trio.Event] = {}
        self._next_channel = 1
        self.client_advertised = trio.Event()
        self.topics = dict(topics or {"/chatter": "std_msgs/msg/String"})

    def channel(self, topic: str, schema_name: str, schema: str | None = None) -> dict[str, Any]:
        cid = self._next_channel
        self._next_channel += 1
        self.channels[topic] = cid
        return {
            "id": cid,
            "topic": topic,
            "encoding": "cdr",
            "schemaName": schema_name,
            "schema": SCHEMAS[schema_name] if schema is None else schema,
            "schemaEncoding": "ros2msg",
        }

    async def greet(self) -> None:
        await self.conn.send(
            json.dumps(
                {
                    "op": "serverInfo",
                    "name": "hostile",
                    "capabilities": ["clientPublish"],
                    "supportedEncodings": ["cdr", "json"],
                    "metadata": {},
                }
            )
        )
        await self.advertise([self.channel(t, s) for t, s in self.topics.items()])

    async def advertise(self, channels: list[dict[str, Any]]) -> None:
        await self.conn.send(json.dumps({"op": "advertise", "channels": channels}))

    async def serve(self) -> None:
        """Read and answer the client until it leaves."""
        try:
            while True:
                message = await self.conn.receive()
                if isinstance(message, bytes):
                    continue
                obj = json.loads(message)
                if obj.get("op") == "subscribe":
                    for s in obj["subscriptions"]:
                        self.subs[s["channelId"]] = s["id"]
                        self._event(s["channelId"]).set()
                elif obj.get("op") == "unsubscribe":
                    gone = set(obj["subscriptionIds"])
                    for cid, sid in list(self.subs.items()):
                        if sid in gone:
                            del self.subs[cid]
                            self._subscribed.pop(cid, None)
                elif obj.get("op") == "advertise":
                    for c in obj["channels"]:
                        self.client_channels[c["id"]] = c["topic"]
                    self.client_advertised.set()
        except ConnectionClosed:
            return

    def _event(self, cid: int) -> trio.Event:
        return self._subscribed.setdefault(cid, trio.Event())

    async def subscribed(self, topic: str) -> None:
        await self._event(self.channels[topic]).wait()

    def is_subscribed(self, topic: str) -> bool:
        return self.channels.get(topic) in self.subs

    async def send_payload(self, topic: str, payload: bytes, log_time: int | None = None) -> None:
        sid = self.subs.get(self.channels[topic])
        if sid is None:
            return
        stamp = time.time_ns() if log_time is None else log_time
        await self.conn.send(b"\x01" + struct.pack("<IQ", sid, stamp) + payload)

    async def send_string(self, topic: str, text: str) -> None:
        await self.send_payload(topic, cdr_string(text))

    async def send_status(self, text: str, level: int = 2) -> None:
        await self.conn.send(json.dumps({"op": "status", "level": level, "message": text}))


class Rosbridge:
    """Just enough of a rosbridge v2 server: ``/rosapi/*`` discovery,
    ``subscribe`` / ``unsubscribe``, JSON ``publish`` ops; other service
    calls and action goals go to ``on_call`` / ``on_goal`` (default: never
    answered)."""

    def __init__(self, conn: Conn, topics: dict[str, str] | None = None) -> None:
        self.conn = conn
        self.topics = dict(topics or {"/chatter": "std_msgs/msg/String"})
        self.services = {"/set_flag": "std_srvs/srv/SetBool"}
        self.action_servers = ["/fibonacci"]
        self.subs: set[str] = set()
        self._subscribed: dict[str, trio.Event] = {}
        self.on_call: Callable[[dict[str, Any]], Awaitable[None]] | None = None
        self.on_goal: Callable[[dict[str, Any]], Awaitable[None]] | None = None
        self.client_advertised = trio.Event()

    async def greet(self) -> None:
        """rosbridge says nothing first."""

    async def serve(self) -> None:
        try:
            while True:
                message = await self.conn.receive()
                if isinstance(message, bytes):
                    continue
                obj = json.loads(message)
                op = obj.get("op")
                if op == "call_service" and str(obj.get("service", "")).startswith("/rosapi/"):
                    await self._rosapi(obj)
                elif op == "call_service" and self.on_call is not None:
                    await self.on_call(obj)
                elif op == "send_action_goal" and self.on_goal is not None:
                    await self.on_goal(obj)
                elif op == "subscribe":
                    self.subs.add(obj["topic"])
                    self._event(obj["topic"]).set()
                elif op == "advertise":
                    self.client_advertised.set()
                elif op == "unsubscribe":
                    self.subs.discard(obj["topic"])
                    self._subscribed.pop(obj["topic"], None)
        except ConnectionClosed:
            return

    async def _rosapi(self, obj: dict[str, Any]) -> None:
        service = obj["service"]
        args = obj.get("args") or {}
        values: Any = {
            "/rosapi/topics": {"topics": list(self.topics), "types": list(self.topics.values())},
            "/rosapi/services": {"services": list(self.services)},
            "/rosapi/service_type": {"type": self.services.get(args.get("service", ""), "")},
            "/rosapi/get_time": {"time": {"sec": 1, "nanosec": 2}},
            "/rosapi/action_servers": {"action_servers": self.action_servers},
        }.get(service, {})
        await self.conn.send(
            json.dumps(
                {
                    "op": "service_response",
                    "service": service,
                    "result": True,
                    "values": values,
                    "id": obj.get("id"),
                }
            )
        )

    def _event(self, topic: str) -> trio.Event:
        return self._subscribed.setdefault(topic, trio.Event())

    async def subscribed(self, topic: str) -> None:
        await self._event(topic).wait()

    def is_subscribed(self, topic: str) -> bool:
        return topic in self.subs

    async def send_string(self, topic: str, text: str) -> None:
        if topic in self.subs:
            await self.conn.send(
                json.dumps({"op": "publish", "topic": topic, "msg": {"data": text}})
            )

    async def send_status(self, text: str, level: str = "error") -> None:
        await self.conn.send(json.dumps({"op": "status", "level": level, "msg": text}))


Bridge = Foxglove | Rosbridge


def bridge(conn: Conn, protocol: str, topics: dict[str, str] | None = None) -> Bridge:
    return Foxglove(conn, topics) if protocol == "foxglove" else Rosbridge(conn, topics)


async def stream_strings(b: Bridge, topic: str, hz: float = 20.0) -> None:
    """Publish ``"0"``, ``"1"``, ... on ``topic`` while subscribed."""
    n = 0
    while True:
        if b.is_subscribed(topic):
            await b.send_string(topic, str(n))
            n += 1
        await trio.sleep(1 / hz)


# -- the server ------------------------------------------------------------------------


async def serve(scenario: str, port: int, args: dict[str, str]) -> None:
    module = importlib.import_module(f"peers.hostile_scenarios.{scenario}")
    protocol = args.get("protocol", getattr(module, "PROTOCOL", "foxglove"))
    args["protocol"] = protocol
    streams: dict[str, GatedStream] = {}

    async def handler(request: WebSocketRequest) -> None:
        if protocol == "foxglove":
            offered = [p for p in request.proposed_subprotocols if p in FOXGLOVE_SUBPROTOCOLS]
            if not offered:
                await request.reject(400, body=b"no foxglove subprotocol offered")
                return
            ws = await request.accept(subprotocol=offered[0])
        else:
            ws = await request.accept()
        stream = streams.pop(str(request.remote))
        conn = Conn(ws, stream, dict(args))
        conn.record("connect", subprotocol=ws.subprotocol)
        try:
            await module.run(conn)
        except ConnectionClosed:
            pass
        except Exception as exc:  # a scenario bug must not take the server down
            conn.record("scenario_error", error=repr(exc))
            traceback.print_exc()
        finally:
            conn.record("disconnect")

    listeners = await trio.open_tcp_listeners(port, host="127.0.0.1")
    server = trio_websocket.WebSocketServer(
        handler,
        [GatedListener(listener, streams) for listener in listeners],
        handler_nursery=None,
        max_message_size=256 * 1024 * 1024,
        connect_timeout=10,
        disconnect_timeout=2,
    )
    async with trio.open_nursery() as nursery:
        await nursery.start(server.run)
        bound = listeners[0].socket.getsockname()[1]
        record("listening", port=bound, scenario=scenario, args=args)
        print(f"PORT {bound}", flush=True)


def main(argv: list[str] | None = None) -> None:
    global _LOG
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("scenario")
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--log")
    parser.add_argument("--arg", action="append", default=[], help="K=V for the scenario")
    ns = parser.parse_args(argv)
    if ns.log:
        _LOG = open(ns.log, "a", encoding="utf-8")  # noqa: SIM115
    args = dict(a.split("=", 1) for a in ns.arg)
    trio.run(serve, ns.scenario, ns.port, args)


if __name__ == "__main__":
    # Run as the importable module, so scenarios share its state.
    from peers.hostile_server import main as _main

    sys.exit(_main())
