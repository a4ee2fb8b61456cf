"""The zenoh peers ``bench/bench_zenoh.py`` starts in subprocesses (not run by hand).

    python bench/_zenoh_publisher.py router tcp/127.0.0.1:PORT
    python bench/_zenoh_publisher.py publisher tcp/127.0.0.1:PORT DOMAIN

``router``: an eclipse-zenoh session in *router* mode listening on exactly
the given endpoint (multicast and gossip scouting off, shared memory off).
It prints ``ready`` once it listens and runs until its stdin closes.

``publisher``: a *client* session to that router (scouting off, shared
memory off) with two rmw_zenoh publishers, each on its exact data key
(``<domain>/bench/<name>/<dds type>/<RIHS01 hash>``) with a publisher
liveliness token as ``rmw_zenoh_cpp`` declares one:

* ``string``: ``std_msgs/msg/String``, 90 characters (a 99-byte CDR payload);
* ``image``: ``sensor_msgs/msg/Image`` 640x480 ``rgb8`` (921,652 bytes).

Both are reliable with congestion control BLOCK: nothing is dropped on the
way, a full link makes ``put`` wait. It prints ``ready <string bytes> <image
bytes>``, then reads commands on stdin, one a line:

* ``burst <string|image> <count>``: build ``count`` attachments (sequence
  numbers 1..count, the current time as the timestamp, this publisher's
  gid), wait until a subscriber matches the key (at most 10 s), put the
  ``count`` samples as fast as the loop goes and print ``done <sent> <start>
  <end>`` (``CLOCK_MONOTONIC`` seconds around the puts, comparable with the
  parent's clock), or ``error <text>``;
* ``paced <string|image> <count> <rate>``: the same, but the puts are paced
  at ``rate`` a second on a fixed schedule (``bench/bench_bandwidth.py``);
* ``quit`` (or the end of stdin): undeclare everything, close, exit.

The attachments are built before the puts so that the publisher's own Python
work, which shares nothing with the measured process, does as little as
possible to cap the rate the subscribers are offered.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from typing import Any, Final

import zenoh

from ros_mobile_bridge.codec import CodecRegistry, type_hash
from ros_mobile_bridge.wire import rmw_zenoh as rz

STRING_TOPIC: Final = "/bench/string"
IMAGE_TOPIC: Final = "/bench/image"
STRING_TYPE: Final = "std_msgs/msg/String"
IMAGE_TYPE: Final = "sensor_msgs/msg/Image"
TOPICS: Final = {"string": (STRING_TOPIC, STRING_TYPE), "image": (IMAGE_TOPIC, IMAGE_TYPE)}
MATCH_TIMEOUT: Final = 10.0


def monotonic() -> float:
    """``CLOCK_MONOTONIC`` in seconds: one clock for every process on the host."""
    return time.clock_gettime(time.CLOCK_MONOTONIC)


def payloads() -> dict[str, bytes]:
    """The CDR payload of each kind: a 90-character String, a 640x480 rgb8 Image."""
    codecs = CodecRegistry()
    string = codecs.encoder(STRING_TYPE, "cdr")({"data": "x" * 90})
    image = codecs.encoder(IMAGE_TYPE, "cdr")(
        {
            "header": {"stamp": {"sec": 0, "nanosec": 0}, "frame_id": "camera"},
            "height": 480,
            "width": 640,
            "encoding": "rgb8",
            "is_bigendian": 0,
            "step": 640 * 3,
            "data": bytes(640 * 480 * 3),
        }
    )
    return {"string": bytes(string), "image": bytes(image)}


def data_key(domain: int, topic: str, type_name: str) -> str:
    """The exact rmw_zenoh data key of ``topic`` (with the type's RIHS01 hash)."""
    return rz.format_key(
        rz.TopicKey(domain, topic, type_name, type_hash(CodecRegistry(), type_name))
    )


def config(mode: str, endpoint: str) -> zenoh.Config:
    """A router listening on ``endpoint`` or a client connecting to it; no
    scouting, no shared memory."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps(mode))
    section = "listen/endpoints" if mode == "router" else "connect/endpoints"
    conf.insert_json5(section, json.dumps([endpoint]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    conf.insert_json5("transport/shared_memory/enabled", "false")
    return conf


def run_router(endpoint: str) -> None:
    """Route until stdin closes."""
    session = zenoh.open(config("router", endpoint))
    try:
        print("ready", flush=True)
        sys.stdin.read()
    finally:
        session.close()  # type: ignore[no-untyped-call]


class Publishers:
    """The session, both publishers and their tokens."""

    def __init__(self, endpoint: str, domain: int) -> None:
        self.session = zenoh.open(config("client", endpoint))
        zid = str(self.session.zid())
        self.payloads = payloads()
        self.publishers: dict[str, Any] = {}
        self.gids: dict[str, bytes] = {}
        self.tokens: list[Any] = []
        node = rz.Token(domain, zid, 0, 0, rz.EntityKind.NODE, "", "/", "bench_publisher")
        self.tokens.append(self.session.liveliness().declare_token(rz.format_token(node)))
        for entity_id, (kind, (topic, type_name)) in enumerate(TOPICS.items(), start=1):
            key = data_key(domain, topic, type_name)
            token_key = rz.format_token(
                rz.Token(
                    domain,
                    zid,
                    0,
                    entity_id,
                    rz.EntityKind.PUBLISHER,
                    "",
                    "/",
                    "bench_publisher",
                    topic,
                    type_name,
                    rz.parse_key(key).type_hash,
                    rz.Qos(),
                )
            )
            self.publishers[kind] = self.session.declare_publisher(
                key,
                congestion_control=zenoh.CongestionControl.BLOCK,
                reliability=zenoh.Reliability.RELIABLE,
            )
            self.gids[kind] = rz.entity_gid(token_key)
            self.tokens.append(self.session.liveliness().declare_token(token_key))
        self.sequence = dict.fromkeys(TOPICS, 0)

    def burst(self, kind: str, count: int, rate: float | None = None) -> str:
        """Put ``count`` samples of ``kind``, as fast as the loop goes or at
        ``rate`` a second; the reply line."""
        publisher = self.publishers[kind]
        payload = zenoh.ZBytes(self.payloads[kind])  # one buffer, no copy per put
        gid, first, now = self.gids[kind], self.sequence[kind] + 1, time.time_ns()
        attachments = [rz.encode_attachment(first + i, now, gid) for i in range(count)]
        self.sequence[kind] += count
        deadline = monotonic() + MATCH_TIMEOUT
        while not publisher.matching_status.matching:
            if monotonic() > deadline:
                return f"error no subscriber matched {kind} within {MATCH_TIMEOUT:g} s"
            time.sleep(0.001)
        put = publisher.put
        start = monotonic()
        for i, attachment in enumerate(attachments):
            if rate is not None and (delay := start + i / rate - monotonic()) > 0:
                time.sleep(delay)
            put(payload, attachment=attachment)
        end = monotonic()
        return f"done {count} {start!r} {end!r}"

    def close(self) -> None:
        for declared in [*self.publishers.values(), *self.tokens]:
            declared.undeclare()
        self.session.close()  # type: ignore[no-untyped-call]


def run_publisher(endpoint: str, domain: int) -> None:
    """Serve ``burst`` commands until ``quit`` or the end of stdin."""
    pubs = Publishers(endpoint, domain)
    try:
        print(f"ready {len(pubs.payloads['string'])} {len(pubs.payloads['image'])}", flush=True)
        for line in sys.stdin:
            words = line.split()
            if not words or words[0] == "quit":
                break
            if words[0] == "burst" and len(words) == 3 and words[1] in TOPICS:
                reply = pubs.burst(words[1], int(words[2]))
            elif words[0] == "paced" and len(words) == 4 and words[1] in TOPICS:
                reply = pubs.burst(words[1], int(words[2]), float(words[3]))
            else:
                reply = f"error unknown command {line.strip()!r}"
            print(reply, flush=True)
    finally:
        pubs.close()


def main() -> None:
    # Ctrl-C reaches the whole process group: the parent cleans up, and closing
    # stdin ends this process
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if len(sys.argv) == 3 and sys.argv[1] == "router":
        run_router(sys.argv[2])
    elif len(sys.argv) == 4 and sys.argv[1] == "publisher":
        run_publisher(sys.argv[2], int(sys.argv[3]))
    else:
        raise SystemExit(__doc__)


if __name__ == "__main__":
    main()
