"""The publisher of ``bench_foxglove.py``: the official Foxglove SDK server in its
own process, so its CPU never shares the client's GIL.

    python bench/_peer.py BACKLOG

Starts ``foxglove.start_server`` on 127.0.0.1 (an ephemeral port) with a
per-client ``message_backlog_size`` of BACKLOG and two CDR channels,
``/bench/string`` (``std_msgs/msg/String``, a 90-character string: 99 bytes)
and ``/bench/image`` (``sensor_msgs/msg/Image``, 640x480 rgb8: 921,652 bytes).
Prints ``port PORT`` when ready, then serves commands on stdin, one a line:

``burst TOPIC COUNT``
    Wait (up to 10 s) until a client subscribes to TOPIC again (a subscription
    newer than the previous command's), publish COUNT messages on it as fast
    as ``Channel.log`` goes, and answer ``done COUNT SECONDS``.
``pace TOPIC COUNT RATE``
    The same wait, then answer ``started`` and publish COUNT messages at RATE
    per second (on a fixed schedule), then answer ``done COUNT SECONDS``.
``quit``
    Stop the server and exit (so does end of input).
"""

from __future__ import annotations

import sys
import threading
import time
from functools import partial
from typing import Any, Final

import foxglove
from foxglove import Channel, Schema
from foxglove.websocket import ServerListener
from rosbags.typesys import Stores, get_typestore

STRING_TOPIC: Final = "/bench/string"
IMAGE_TOPIC: Final = "/bench/image"
STRING_TYPE: Final = "std_msgs/msg/String"
IMAGE_TYPE: Final = "sensor_msgs/msg/Image"
STRING_CHARS: Final = 90
WIDTH: Final = 640
HEIGHT: Final = 480

_STORE = get_typestore(Stores.ROS2_JAZZY)


def cdr(typename: str, **fields: Any) -> bytes:
    """Serialize a bundled ROS 2 message from keyword fields."""
    cls = _STORE.types[typename]
    return bytes(_STORE.serialize_cdr(cls(**fields), typename))


def payloads() -> dict[str, bytes]:
    """The payload published on each topic."""
    import numpy as np

    header = _STORE.types["std_msgs/msg/Header"](
        stamp=_STORE.types["builtin_interfaces/msg/Time"](sec=1, nanosec=2), frame_id="camera"
    )
    pixels = np.random.default_rng(0).integers(0, 256, WIDTH * HEIGHT * 3, dtype=np.uint8)
    return {
        STRING_TOPIC: cdr(STRING_TYPE, data="x" * STRING_CHARS),
        IMAGE_TOPIC: cdr(
            IMAGE_TYPE,
            header=header,
            height=HEIGHT,
            width=WIDTH,
            encoding="rgb8",
            is_bigendian=0,
            step=WIDTH * 3,
            data=pixels,
        ),
    }


class _Listener(ServerListener):
    """Counts subscriptions per topic (called from the server's threads)."""

    def __init__(self) -> None:
        self.cond = threading.Condition()
        self.subscribes: dict[str, int] = {}

    def on_subscribe(self, client: Any, channel: Any) -> None:
        with self.cond:
            self.subscribes[channel.topic] = self.subscribes.get(channel.topic, 0) + 1
            self.cond.notify_all()

    def on_unsubscribe(self, client: Any, channel: Any) -> None:
        pass

    def newer(self, topic: str, seen: dict[str, int]) -> bool:
        """Whether ``topic`` got a subscription since ``seen`` (hold ``cond``)."""
        return self.subscribes.get(topic, 0) > seen[topic]


def main() -> None:
    backlog = int(sys.argv[1]) if len(sys.argv) > 1 else 1024
    listener = _Listener()
    context = foxglove.Context()
    server = foxglove.start_server(
        name="rmb-bench",
        host="127.0.0.1",
        port=0,
        context=context,
        server_listener=listener,
        supported_encodings=["cdr"],
        message_backlog_size=backlog,
    )
    data = payloads()
    types = {STRING_TOPIC: STRING_TYPE, IMAGE_TOPIC: IMAGE_TYPE}
    channels: dict[str, Channel] = {}
    for topic, typename in types.items():
        msgdef, _ = _STORE.generate_msgdef(typename, ros_version=2)
        channels[topic] = Channel(
            topic,
            message_encoding="cdr",
            schema=Schema(name=typename, encoding="ros2msg", data=msgdef.encode()),
            context=context,
        )
    seen: dict[str, int] = dict.fromkeys(types, 0)
    print(f"port {server.port}", flush=True)
    try:
        for line in sys.stdin:
            words = line.split()
            if not words:
                continue
            if words[0] == "quit":
                break
            command = words[0]
            if (command, len(words)) not in (("burst", 3), ("pace", 4)) or words[1] not in channels:
                print(f"error bad command {line.strip()!r}", flush=True)
                continue
            topic, count = words[1], int(words[2])
            with listener.cond:
                ok = listener.cond.wait_for(partial(listener.newer, topic, seen), timeout=10.0)
                seen[topic] = listener.subscribes.get(topic, 0)
            if not ok:
                print(f"error no new subscriber on {topic}", flush=True)
                continue
            log = channels[topic].log
            payload = data[topic]
            start = time.perf_counter()
            if command == "burst":
                for _ in range(count):
                    log(payload)
            else:
                print("started", flush=True)
                period = 1.0 / float(words[3])
                for i in range(count):
                    delay = start + i * period - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                    log(payload)
            print(f"done {count} {time.perf_counter() - start:.6f}", flush=True)
    finally:
        for ch in channels.values():
            ch.close()
        server.stop()


if __name__ == "__main__":
    main()
