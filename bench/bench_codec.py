"""Benchmark of ros_mobile_bridge.codec decoding and encoding (stand-alone script).

    .venv/bin/python bench/bench_codec.py [--seconds 0.5]

Measures decodes per second for a ~100-byte std_msgs/msg/String payload, a
nav_msgs/msg/Odometry and a 640x480 rgb8 sensor_msgs/msg/Image:

* our decoder (payload -> dict) from a memoryview and from a bytes object;
* raw rosbags (payload -> rosbags dataclass, no dict) from a memoryview and
  from bytes, through ``Typestore.deserialize_cdr`` and through the message's
  generated function directly (what our decoder calls);
* the dict-conversion overhead: our decoder minus the direct rosbags call;

and encodes per second for the same messages.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ros_mobile_bridge.codec import CodecRegistry


def rate(func: Callable[[], object], seconds: float) -> float:
    """Calls per second of ``func``, measured for about ``seconds``."""
    func()
    batch = 1
    while True:  # size a batch to ~1/20 of the budget
        start = time.perf_counter()
        for _ in range(batch):
            func()
        elapsed = time.perf_counter() - start
        if elapsed > seconds / 20:
            break
        batch *= 2
    best = 0.0
    deadline = time.perf_counter() + seconds
    while time.perf_counter() < deadline:
        start = time.perf_counter()
        for _ in range(batch):
            func()
        best = max(best, batch / (time.perf_counter() - start))
    return best


def fmt_rate(value: float) -> str:
    if value >= 1e6:
        return f"{value / 1e6:8.2f} M/s"
    if value >= 1e3:
        return f"{value / 1e3:8.1f} k/s"
    return f"{value:8.1f}  /s"


def fmt_us(value: float) -> str:
    return f"{value * 1e6:8.2f} us"


def raw_rosbags(reg: CodecRegistry, name: str) -> tuple[Any, Any]:
    """The rosbags typestore and msgdef our decoder for ``name`` uses (private API,
    benchmark only)."""
    gen = reg._gen
    assert gen is not None
    return gen.store, gen.store.get_msgdef(name)


def bench_case(
    reg: CodecRegistry, label: str, name: str, data: dict[str, Any], seconds: float
) -> None:
    """Measure and print one message type."""
    encode = reg.encoder(name, "cdr")
    decode = reg.decoder(name, "cdr")
    payload = encode(data)
    view = memoryview(payload)
    store, msgdef = raw_rosbags(reg, name)
    func, cls = msgdef.deserialize_cdr_le, msgdef.cls

    results = {
        "decoder(memoryview) -> dict": rate(lambda: decode(view), seconds),
        "decoder(bytes) -> dict": rate(lambda: decode(payload), seconds),  # type: ignore[arg-type]
        "rosbags deserialize_cdr(memoryview), no dict": rate(
            lambda: store.deserialize_cdr(view, name), seconds
        ),
        "rosbags deserialize_cdr(bytes), no dict": rate(
            lambda: store.deserialize_cdr(payload, name), seconds
        ),
        "rosbags generated func(view[4:]), no dict": rate(
            lambda: func(view[4:], 0, cls, store), seconds
        ),
        "encoder(dict) -> bytes": rate(lambda: encode(data), seconds),
    }
    print(f"{label} ({len(payload):,} byte payload)")
    for what, value in results.items():
        print(f"  {what:<46} {fmt_rate(value):>12} {fmt_us(1 / value):>11}")
    ours = results["decoder(memoryview) -> dict"]
    direct = results["rosbags generated func(view[4:]), no dict"]
    mv = results["rosbags deserialize_cdr(memoryview), no dict"]
    by = results["rosbags deserialize_cdr(bytes), no dict"]
    print(
        f"  {'dict conversion + checks overhead':<46} {'':>12} {fmt_us(1 / ours - 1 / direct):>11}"
    )
    print(f"  {'rosbags: memoryview speed-up over bytes':<46} {mv / by:>10.1f} x\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=0.5, help="time per measurement")
    args = parser.parse_args()
    seconds: float = args.seconds

    reg = CodecRegistry()
    cases: list[tuple[str, str, dict[str, Any]]] = [
        ("String", "std_msgs/msg/String", {"data": "x" * 91}),
        (
            "Odometry",
            "nav_msgs/msg/Odometry",
            {
                "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "odom"},
                "child_frame_id": "base_link",
                "pose": {"pose": {"position": {"x": 1.0}}, "covariance": np.arange(36.0)},
            },
        ),
        (
            "Image 640x480 rgb8",
            "sensor_msgs/msg/Image",
            {
                "header": {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "camera"},
                "height": 480,
                "width": 640,
                "encoding": "rgb8",
                "step": 640 * 3,
                "data": np.random.default_rng(0).integers(0, 256, 640 * 480 * 3, dtype=np.uint8),
            },
        ),
    ]

    try:
        rosbags_version = importlib.metadata.version("rosbags")
    except importlib.metadata.PackageNotFoundError:
        rosbags_version = "?"
    print(
        f"python {platform.python_version()} ({sys.implementation.name}), "
        f"numpy {np.__version__}, rosbags {rosbags_version}, "
        f"{platform.machine()}"
    )
    print(f"{seconds:g} s per measurement, best batch rate\n")
    for label, name, data in cases:
        bench_case(reg, label, name, data, seconds)


if __name__ == "__main__":
    main()
