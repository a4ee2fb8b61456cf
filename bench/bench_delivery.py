"""Delivered messages per second through a subscription, dicts against
classes (stand-alone script).

    .venv/bin/python bench/bench_delivery.py [--messages 20000] [--rounds 5]

A drain of ``nav_msgs/msg/Odometry`` through the library's own consumer path
(the frame queue, the subscription's ``async for``, the decode on the
consumer's pull, the ``Message``), with each transport's payload form and
both decoders, in one run:

* CDR (Foxglove, Zenoh, rosbridge ``cbor-raw``): the payload decoded to a
  dict (``CodecRegistry.dict_decoder``, what a message was before classes)
  against to an instance (``CodecRegistry.decoder``);
* rosbridge JSON: the message's JSON text parsed (``json.loads``: a dict,
  as before classes) against parsed and converted to an instance
  (``CodecRegistry.dict_converter``). Over rosbridge the reader parses the
  frame, so the parse is in both forms' cost, as it is here.

No network and no peer: the frames are queued ahead and drained, so the
figure is the consumer's cost per message, every message delivered (the
fates are counted and checked). Ratios are against the dict form of the
same transport, measured in the same run (best of ``--rounds``)."""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import anyio
import numpy as np

from ros_mobile_bridge import jsonable
from ros_mobile_bridge.codec import CodecRegistry
from ros_mobile_bridge.flow import RawFrame
from ros_mobile_bridge.flow._subscription import FrameQueue, Subscription
from ros_mobile_bridge.interfaces.nav_msgs.msg import Odometry

TYPE = "nav_msgs/msg/Odometry"


def _odometry() -> Odometry:
    message = Odometry()
    message.header.frame_id = "odom"
    message.child_frame_id = "base_link"
    message.pose.pose.position.x = 1.25
    message.pose.covariance = np.arange(36.0)
    message.twist.covariance = np.arange(36.0)
    return message


async def _drain(payload: memoryview, decode: Callable[[memoryview], Any], count: int) -> float:
    """Seconds of CPU to deliver ``count`` frames; checks every fate."""
    import logging

    queue = FrameQueue(buffer=count + 1)
    sub: Subscription[Any] = Subscription(
        "/odom", queue, logger=logging.getLogger("bench"), decode=True
    )
    for _ in range(count):
        queue.offer(RawFrame("/odom", TYPE, "cdr", payload, None, 0, decode))
    queue.close()
    start = time.thread_time()
    delivered = 0
    async for msg in sub:
        assert msg.decode_error is None
        delivered += 1
    elapsed = time.thread_time() - start
    stats = sub.stats
    assert delivered == count == stats.delivered == stats.received, (delivered, stats)
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--messages", type=int, default=20000)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--backend", choices=("asyncio", "trio"), default="asyncio")
    args = parser.parse_args()
    registry = CodecRegistry()
    message = _odometry()
    cdr = memoryview(registry.encoder(TYPE, "cdr")(message))
    text = memoryview(json.dumps(jsonable(message)).encode())
    convert = registry.dict_converter(TYPE)
    assert convert is not None
    forms: dict[str, tuple[memoryview, Callable[[memoryview], Any]]] = {
        "CDR -> dict": (cdr, registry.dict_decoder(TYPE)),
        "CDR -> class": (cdr, registry.decoder(TYPE, "cdr")),
        "rosbridge JSON -> dict": (text, lambda payload: json.loads(bytes(payload))),
        "rosbridge JSON -> class": (text, lambda payload: convert(json.loads(bytes(payload)))),
    }
    best: dict[str, float] = {}
    for _ in range(args.rounds):
        for label, (payload, decode) in forms.items():
            seconds = anyio.run(_drain, payload, decode, args.messages, backend=args.backend)
            best[label] = max(best.get(label, 0.0), args.messages / seconds)
    print(
        f"{TYPE} delivered per second of CPU ({args.backend}), {args.messages} messages, "
        f"best of {args.rounds}; every message delivered"
    )
    for label, value in best.items():
        base = label.replace("class", "dict")
        print(f"  {label:<34} {value / 1e3:8.1f} k/s   {value / best[base]:5.2f}x the dict form")


if __name__ == "__main__":
    main()
