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
``stamped TOPIC COUNT RATE``
    As ``pace``, but each message carries its sequence number (from 1), so
    that no two are byte for byte the same (as a camera's stamps make them):
    see :func:`stamp_into` (``bench_bandwidth.py``).
``quit``
    Stop the server and exit (so does end of input).

``python bench/_peer.py reliability BACKLOG`` is the server of
``bench_reliability.py`` instead (see :func:`reliability_main`): an image
stream at a settable rate, and client publishing with every ``/cmd_vel``
message stamped on receipt. ``python bench/_peer.py publisher URL COUNT
SEED`` is an idle second client publishing control frames to it, and
``python bench/_peer.py rxqueue PORT`` watches its socket receive queues (see
:func:`publisher_main`, :func:`rxqueue_main`).
"""

from __future__ import annotations

import json
import struct
import sys
import threading
import time
from functools import partial
from typing import Any, Final

import foxglove
from foxglove import Channel, Schema
from foxglove.websocket import Capability, ServerListener
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


def stamp_into(topic: str, payload: bytearray, seq: int) -> None:
    """Write ``seq`` into a copy of a payload of :func:`payloads`: the image's
    ``header.stamp.sec`` (int32 at offset 4, after the CDR header); the
    string's first 8 characters, as decimal digits (offset 8, after the
    header and the length)."""
    if topic == IMAGE_TOPIC:
        struct.pack_into("<i", payload, 4, seq)
    else:
        payload[8:16] = b"%08d" % seq


def stamp_of(topic: str, payload: bytes | memoryview) -> int:
    """The sequence number :func:`stamp_into` wrote."""
    if topic == IMAGE_TOPIC:
        return int(struct.unpack_from("<i", payload, 4)[0])
    return int(bytes(payload[8:16]))


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
            known = (("burst", 3), ("pace", 4), ("stamped", 4))
            if (command, len(words)) not in known or words[1] not in channels:
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
                stamped = bytearray(payload) if command == "stamped" else None
                for i in range(count):
                    delay = start + i * period - time.perf_counter()
                    if delay > 0:
                        time.sleep(delay)
                    if stamped is None:
                        log(payload)
                    else:
                        stamp_into(topic, stamped, i + 1)
                        log(bytes(stamped))
            print(f"done {count} {time.perf_counter() - start:.6f}", flush=True)
    finally:
        for ch in channels.values():
            ch.close()
        server.stop()


# -- the reliability peer (bench_reliability.py) ---------------------------------------

CMD_TOPIC: Final = "/cmd_vel"
TWIST_TYPE: Final = "geometry_msgs/msg/Twist"


def twist_seq(data: bytes, encoding: str) -> int:
    """The sequence number ``bench_reliability.py`` puts in ``linear.y`` of a
    Twist (CDR or JSON); 0 for anything else (the teardown's zero Twist)."""
    try:
        if encoding == "cdr":
            if len(data) < 20:
                return 0
            fmt = "<d" if data[1] == 1 else ">d"  # encapsulation: CDR_LE or CDR_BE
            return int(struct.unpack_from(fmt, data, 12)[0])  # header 4 + linear.x 8
        if encoding == "json":
            return int(json.loads(data).get("linear", {}).get("y", 0))
    except (ValueError, TypeError, AttributeError, struct.error):
        pass
    return 0


class ReliabilityListener(_Listener):
    """Also accepts client publishing: every message a client publishes is
    stamped with ``time.time_ns()`` as the first thing the callback does, and
    kept (decoded later, off the callback)."""

    def __init__(self) -> None:
        super().__init__()
        self.client_channels: dict[tuple[int, int], tuple[str, str]] = {}
        self.inbox: list[tuple[int, int, bytes, int]] = []
        self.inbox_lock = threading.Lock()

    def on_client_advertise(self, client: Any, channel: Any) -> None:
        with self.cond:
            self.client_channels[(client.id, channel.id)] = (channel.topic, channel.encoding)

    def on_message_data(self, client: Any, client_channel_id: int, data: bytes) -> None:
        now = time.time_ns()
        with self.inbox_lock:
            self.inbox.append((client.id, client_channel_id, data, now))

    def take_commands(self, topic: str) -> list[tuple[int, int]]:
        """(sequence number, receive time ns) of every message received on
        ``topic`` since the last call, in arrival order. Messages on other
        topics stay for their own call."""
        with self.cond:
            channels = dict(self.client_channels)
        with self.inbox_lock:
            inbox, self.inbox = self.inbox, []
        out: list[tuple[int, int]] = []
        other: list[tuple[int, int, bytes, int]] = []
        for client_id, channel_id, data, ns in inbox:
            name, encoding = channels.get((client_id, channel_id), ("", ""))
            if name != topic:
                other.append((client_id, channel_id, data, ns))
            elif (seq := twist_seq(data, encoding)) > 0:
                out.append((seq, ns))
        with self.inbox_lock:
            self.inbox[:0] = other
        return out


class ImageStream:
    """A thread that logs ``payload`` on ``channel`` at a settable rate, on a
    fixed schedule that never bursts to catch up. It sleeps between messages,
    so it holds this process's GIL only inside ``Channel.log``."""

    def __init__(self, channel: Channel, payload: bytes) -> None:
        self._channel = channel
        self._payload = payload
        self._rate = 0.0
        self._cond = threading.Condition()
        self._stop = False
        self.logged = 0
        self._thread = threading.Thread(target=self._run, name="image-stream", daemon=True)
        self._thread.start()

    def set_rate(self, rate: float) -> None:
        with self._cond:
            self._rate = rate
            self._cond.notify_all()

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        log, payload = self._channel.log, self._payload
        rate = 0.0
        due = time.perf_counter()
        while True:
            with self._cond:
                while self._rate <= 0 and not self._stop:
                    self._cond.wait()
                if self._stop:
                    return
                if self._rate != rate:
                    rate, due = self._rate, time.perf_counter()
            period = 1.0 / rate
            now = time.perf_counter()
            if due > now:
                time.sleep(due - now)
            elif now - due > period:
                due = now  # late: drop the missed slots rather than burst
            log(payload)
            self.logged += 1
            due += period


class WakeProbe:
    """A thread of this process that sleeps 1 ms at a time and records how
    late it wakes up: what any Python callback here (the ``/cmd_vel``
    receipt stamp included) waits for a CPU and for the GIL."""

    def __init__(self) -> None:
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.late_ns: list[int] = []

    def start(self) -> None:
        self.stop()
        self.late_ns = []
        self._stop.clear()
        self._thread = threading.Thread(target=self._run, name="wake-probe", daemon=True)
        self._thread.start()

    def stop(self) -> list[int]:
        if self._thread is not None:
            self._stop.set()
            self._thread.join(timeout=5)
            self._thread = None
        return self.late_ns

    def _run(self) -> None:
        late, clock = self.late_ns, time.perf_counter_ns
        while not self._stop.is_set():
            due = clock() + 1_000_000
            time.sleep(0.001)
            late.append(clock() - due)


def reliability_main(backlog: int) -> None:
    """``python bench/_peer.py reliability BACKLOG``: the server of
    ``bench_reliability.py``. It offers ``/bench/image`` (640x480 rgb8, CDR)
    and accepts client publishing (``clientPublish``, CDR and JSON). Prints
    ``port PORT``, then serves commands on stdin, one a line:

    ``stream RATE``
        Log the image at RATE per second from now on (0 stops); ``ok``.
    ``commands [TOPIC]``
        ``commands N SEQ:NS ...``: every message clients published on TOPIC
        (default ``/cmd_vel``) since the last ``commands``, as the sequence
        number in its ``linear.y`` and the server's ``time.time_ns()`` at
        receipt. Messages on other topics are discarded.
    ``logged``
        ``logged N``: images logged since start.
    ``probe start``, ``probe stop``
        Start a :class:`WakeProbe` (``ok``); stop it and answer
        ``probe LATE_US ...``, how late each 1 ms sleep woke (microseconds).
    ``quit``
        Stop and exit (so does end of input).
    """
    sys.setswitchinterval(0.0005)  # the receipt stamp must not wait 5 ms for the GIL
    listener = ReliabilityListener()
    context = foxglove.Context()
    server = foxglove.start_server(
        name="rmb-bench-reliability",
        host="127.0.0.1",
        port=0,
        context=context,
        server_listener=listener,
        capabilities=[Capability.ClientPublish],
        supported_encodings=["cdr", "json"],
        message_backlog_size=backlog,
    )
    msgdef, _ = _STORE.generate_msgdef(IMAGE_TYPE, ros_version=2)
    channel = Channel(
        IMAGE_TOPIC,
        message_encoding="cdr",
        schema=Schema(name=IMAGE_TYPE, encoding="ros2msg", data=msgdef.encode()),
        context=context,
    )
    stream = ImageStream(channel, payloads()[IMAGE_TOPIC])
    probe = WakeProbe()
    print(f"port {server.port}", flush=True)
    try:
        for line in sys.stdin:
            words = line.split()
            if not words:
                continue
            if words[0] == "quit":
                break
            if words[0] == "stream" and len(words) == 2:
                stream.set_rate(float(words[1]))
                print("ok", flush=True)
            elif words[0] == "commands" and len(words) <= 2:
                got = listener.take_commands(words[1] if len(words) == 2 else CMD_TOPIC)
                print("commands", len(got), *(f"{s}:{ns}" for s, ns in got), flush=True)
            elif words[0] == "logged" and len(words) == 1:
                print(f"logged {stream.logged}", flush=True)
            elif words[0] == "probe" and words[1:] == ["start"]:
                probe.start()
                print("ok", flush=True)
            elif words[0] == "probe" and words[1:] == ["stop"]:
                print("probe", *(ns // 1000 for ns in probe.stop()), flush=True)
            else:
                print(f"error bad command {line.strip()!r}", flush=True)
    finally:
        probe.stop()
        stream.close()
        channel.close()
        server.stop()


IDLE_TOPIC: Final = "/cmd_vel_idle"


def publisher_main(url: str, count: int, seed: int) -> None:
    """``python bench/_peer.py publisher URL COUNT SEED``: a second client with
    nothing else to do (``websockets``' synchronous client, no subscription),
    the baseline for what the server and this machine add to a control frame.
    Advertises ``/cmd_vel_idle`` (Twist, CDR) and prints ``ready``; on a line
    from stdin publishes COUNT Twists 15-25 ms apart (the sequence number 1..
    COUNT in ``linear.y``), then prints ``sent SEQ:NS ...`` with
    ``time.time_ns()`` taken just before each send, and exits."""
    import random

    from websockets.sync.client import connect
    from websockets.typing import Subprotocol

    with connect(url, subprotocols=[Subprotocol("foxglove.sdk.v1.1")], compression=None) as ws:
        channel = {"id": 1, "topic": IDLE_TOPIC, "encoding": "cdr", "schemaName": TWIST_TYPE}
        ws.send(json.dumps({"op": "advertise", "channels": [channel]}))
        print("ready", flush=True)
        sys.stdin.readline()
        rng = random.Random(seed)
        header = struct.pack("<BI", 1, 1) + b"\x00\x01\x00\x00"  # message data, channel 1; CDR_LE
        stamps: list[str] = []
        for seq in range(1, count + 1):
            time.sleep(rng.uniform(0.015, 0.025))
            frame = header + struct.pack("<6d", 0.1, float(seq), 0.0, 0.0, 0.0, 0.2)
            stamps.append(f"{seq}:{time.time_ns()}")
            ws.send(frame)
    print("sent", *stamps, flush=True)


def rxqueue_main(port: int) -> None:
    """``python bench/_peer.py rxqueue PORT`` (Linux): until a line arrives on
    stdin, poll ``/proc/net/tcp`` every 0.2 ms and record every change
    of the receive queue (bytes the kernel holds that the process has not
    read yet) of the sockets whose local port is PORT: the server's side of
    each connection. Then print ``rxqueue T_NS:REMOTE:BYTES ...`` and exit."""
    suffix = f":{port:04X}"
    changes: list[str] = []
    last: dict[str, int] = {}
    done = threading.Event()

    def wait_for_input() -> None:
        sys.stdin.readline()
        done.set()

    threading.Thread(target=wait_for_input, daemon=True).start()
    print("ready", flush=True)
    while not done.is_set():
        now = time.time_ns()
        with open("/proc/net/tcp") as table:
            next(table)
            for line in table:
                fields = line.split()
                if fields[1].endswith(suffix):
                    rx = int(fields[4].split(":")[1], 16)
                    if last.get(fields[2]) != rx:
                        last[fields[2]] = rx
                        changes.append(f"{now}:{fields[2]}:{rx}")
        time.sleep(0.0002)  # about 0.3 ms resolution for a fraction of a core
    print("rxqueue", *changes, flush=True)


# -- the scale peer (bench_scale.py) ------------------------------------------------

SCALE_TOPIC: Final = "/scale/tick"


def scale_main(rate: float) -> None:
    """``python bench/_peer.py scale RATE``: a Foxglove SDK server with one
    ``std_msgs/msg/String`` channel, ``/scale/tick``, logged RATE times a
    second (a fixed schedule, from the start) whether or not anyone
    subscribes; every message carries its sequence number. Prints ``port
    PORT``, then ``subscribers N`` after each ``count`` line on stdin (how
    many subscriptions to the channel exist now); exits on ``quit`` or end of
    input. The per-client backlog stays at the SDK's default."""
    subscribers = 0
    lock = threading.Lock()

    class Listener(ServerListener):
        def on_subscribe(self, client: Any, channel: Any) -> None:
            nonlocal subscribers
            with lock:
                subscribers += 1

        def on_unsubscribe(self, client: Any, channel: Any) -> None:
            nonlocal subscribers
            with lock:
                subscribers -= 1

    context = foxglove.Context()
    server = foxglove.start_server(
        name="rmb-bench-scale",
        host="127.0.0.1",
        port=0,
        context=context,
        server_listener=Listener(),
        supported_encodings=["cdr"],
    )
    msgdef, _ = _STORE.generate_msgdef(STRING_TYPE, ros_version=2)
    channel = Channel(
        SCALE_TOPIC,
        message_encoding="cdr",
        schema=Schema(name=STRING_TYPE, encoding="ros2msg", data=msgdef.encode()),
        context=context,
    )
    stop = threading.Event()

    def publish() -> None:
        period = 1.0 / rate
        start = time.perf_counter()
        i = 0
        while not stop.is_set():
            delay = start + i * period - time.perf_counter()
            if delay > 0:
                stop.wait(delay)
            channel.log(cdr(STRING_TYPE, data=f"tick {i:010d}"))
            i += 1

    publisher = threading.Thread(target=publish, daemon=True)
    publisher.start()
    print(f"port {server.port}", flush=True)
    try:
        for line in sys.stdin:
            if line.strip() == "quit":
                break
            if line.strip() == "count":
                with lock:
                    print(f"subscribers {subscribers}", flush=True)
    finally:
        stop.set()
        publisher.join(timeout=2)
        channel.close()
        server.stop()


if __name__ == "__main__":
    if sys.argv[1:2] == ["reliability"]:
        reliability_main(int(sys.argv[2]) if len(sys.argv) > 2 else 8)
    elif sys.argv[1:2] == ["rxqueue"]:
        rxqueue_main(int(sys.argv[2]))
    elif sys.argv[1:2] == ["publisher"]:
        publisher_main(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    elif sys.argv[1:2] == ["scale"]:
        scale_main(float(sys.argv[2]) if len(sys.argv) > 2 else 20.0)
    else:
        main()
