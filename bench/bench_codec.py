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

Then a table of the generated class codec (``codec._cdr``: payload -> message
class instance, instance -> payload) for seven messages (``std_msgs/String``,
``nav_msgs/Odometry``, ``sensor_msgs/JointState`` with 8 named joints,
``tf2_msgs/TFMessage`` with 10 transforms, ``sensor_msgs/Imu``, a 640x480
rgb8 ``sensor_msgs/Image``, a 100,000-point ``sensor_msgs/PointCloud2``):
decodes per second of the class decoder, the dict decoder, rosbags'
``Typestore.deserialize_cdr`` and mcap-ros2-support-fast's decoder (skipped
when it is not installed), all from the same memoryview, with the ratios;
encodes per second of the class encoder and rosbags' ``serialize_cdr``, and
whether the two give the same bytes. Each rate is the best of ``--rounds``
rounds taking turns between the contenders, timed in CPU time of the
thread (``time.thread_time``: other processes on the machine do not count).

    .venv/bin/python bench/bench_codec.py --classes-only [--seconds 0.2 --rounds 5]
"""

from __future__ import annotations

import argparse
import functools
import importlib.metadata
import platform
import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ros_mobile_bridge.codec import CodecRegistry


def rate(
    func: Callable[[], object], seconds: float, clock: Callable[[], float] = time.perf_counter
) -> float:
    """Calls per second of ``func``, measured for about ``seconds`` (of ``clock``)."""
    func()
    batch = 1
    while True:  # size a batch to ~1/20 of the budget
        start = clock()
        for _ in range(batch):
            func()
        elapsed = clock() - start
        if elapsed > seconds / 20:
            break
        batch *= 2
    best = 0.0
    deadline = clock() + seconds
    while clock() < deadline:
        start = clock()
        for _ in range(batch):
            func()
        best = max(best, batch / max(clock() - start, 1e-9))
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
    decode = reg.dict_decoder(name)  # the dict form (what decoder() gave before classes)
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


def class_cases() -> list[tuple[str, str, dict[str, Any]]]:
    """The messages of the class codec table: (label, type, dict)."""
    rng = np.random.default_rng(0)
    header = {"stamp": {"sec": 1, "nanosec": 2}, "frame_id": "base_link"}
    points = 100_000
    return [
        ("String", "std_msgs/msg/String", {"data": "x" * 91}),
        (
            "Odometry",
            "nav_msgs/msg/Odometry",
            {
                "header": header,
                "child_frame_id": "base_footprint",
                "pose": {"pose": {"position": {"x": 1.0}}, "covariance": np.arange(36.0)},
                "twist": {"covariance": np.arange(36.0)},
            },
        ),
        (
            "JointState 8",
            "sensor_msgs/msg/JointState",
            {
                "header": header,
                "name": [f"joint_{i}" for i in range(8)],
                "position": rng.random(8),
                "velocity": rng.random(8),
                "effort": rng.random(8),
            },
        ),
        (
            "TFMessage 10",
            "tf2_msgs/msg/TFMessage",
            {
                "transforms": [
                    {
                        "header": header,
                        "child_frame_id": f"link_{i}",
                        "transform": {"translation": {"x": float(i)}, "rotation": {"w": 1.0}},
                    }
                    for i in range(10)
                ]
            },
        ),
        (
            "Imu",
            "sensor_msgs/msg/Imu",
            {
                "header": header,
                "orientation": {"w": 1.0},
                "orientation_covariance": rng.random(9),
                "angular_velocity_covariance": rng.random(9),
                "linear_acceleration_covariance": rng.random(9),
            },
        ),
        (
            "Image 640x480",
            "sensor_msgs/msg/Image",
            {
                "header": header,
                "height": 480,
                "width": 640,
                "encoding": "rgb8",
                "step": 640 * 3,
                "data": rng.integers(0, 256, 640 * 480 * 3, dtype=np.uint8),
            },
        ),
        (
            "PointCloud2 100k",
            "sensor_msgs/msg/PointCloud2",
            {
                "header": header,
                "height": 1,
                "width": points,
                "fields": [
                    {"name": name, "offset": 4 * i, "datatype": 7, "count": 1}
                    for i, name in enumerate(("x", "y", "z", "intensity"))
                ],
                "point_step": 16,
                "row_step": 16 * points,
                "data": rng.integers(0, 256, 16 * points, dtype=np.uint8),
                "is_dense": True,
            },
        ),
    ]


def mcap_fast_decoder(reg: CodecRegistry, name: str) -> Callable[[memoryview], Any] | None:
    """mcap-ros2-support-fast's decoder of ``name`` (through its public
    ``DecoderFactory``, from the concatenated ``.msg`` schema), or None when
    it is not installed."""
    try:
        from mcap_ros2_support_fast.decoder import DecoderFactory
    except ImportError:
        return None

    class Schema:
        id = 1
        encoding = "ros2msg"

        def __init__(self, name: str, data: bytes) -> None:
            self.name = name
            self.data = data

    decoder = DecoderFactory().decoder_for("cdr", Schema(name, reg.ros2msg_text(name).encode()))
    assert decoder is not None
    return decoder


def fmt_ratio(value: float | None) -> str:
    return "-" if value is None else f"{value:.2f}x"


def class_row(
    reg: CodecRegistry, label: str, name: str, data: dict[str, Any], seconds: float, rounds: int
) -> None:
    """Measure and print one row of the class codec table."""
    from ros_mobile_bridge.codec._cdr import build_class_decoder
    from ros_mobile_bridge.codec._cdr_encode import build_class_encoder
    from ros_mobile_bridge.interfaces._base import message_class

    clock = time.thread_time
    key, msgdef = reg._find_ros(name)
    defs = reg._closure(key, msgdef)
    decode = build_class_decoder(key, defs, message_class)
    encode = build_class_encoder(key, defs, message_class)
    payload = reg.encoder(name, "cdr")(data)
    view = memoryview(payload)
    store, _msgdef = raw_rosbags(reg, key)
    dict_decode = reg.dict_decoder(name)
    fast = mcap_fast_decoder(reg, key)
    instance = decode(view)
    native = store.deserialize_cdr(view, key)
    same = bytes(encode(instance)) == bytes(store.serialize_cdr(native, key, little_endian=True))
    contenders: dict[str, Callable[[], object]] = {
        "ours": lambda: decode(view),
        "dict": lambda: dict_decode(view),
        "rosbags": lambda: store.deserialize_cdr(view, key),
        "enc ours": lambda: encode(instance),
        "enc rosbags": lambda: store.serialize_cdr(native, key, little_endian=True),
    }
    if fast is not None:
        contenders["mcap"] = lambda: fast(view)  # type: ignore[misc]
    best: dict[str, float] = {}
    for _ in range(rounds):
        for what, func in contenders.items():
            best[what] = max(best.get(what, 0.0), rate(func, seconds, clock))
    mcap = best.get("mcap")
    print(
        f"{label:<17} {len(payload):>9,} | {fmt_rate(best['ours']):>10} "
        f"{fmt_rate(best['dict']):>10} {fmt_rate(best['rosbags']):>10} "
        f"{fmt_rate(mcap) if mcap else '-':>10} "
        f"{fmt_ratio(best['ours'] / best['rosbags']):>8} "
        f"{fmt_ratio(best['ours'] / mcap if mcap else None):>7} "
        f"{fmt_ratio(best['ours'] / best['dict']):>7} | "
        f"{fmt_rate(best['enc ours']):>10} {fmt_rate(best['enc rosbags']):>10} "
        f"{fmt_ratio(best['enc ours'] / best['enc rosbags']):>7} {'yes' if same else 'NO':>5}"
    )


def class_table(seconds: float, rounds: int) -> None:
    """Measure and print the class codec table (see the module docstring)."""
    try:
        mcap_version: str | None = importlib.metadata.version("mcap-ros2-support-fast")
    except importlib.metadata.PackageNotFoundError:
        mcap_version = None
    print(
        "class codec (codec._cdr): calls per second, best of "
        f"{rounds} rounds of {seconds:g} s CPU time each; mcap-ros2-support-fast "
        + (mcap_version or "is not installed: its column is skipped")
    )
    head = (
        f"{'message':<17} {'bytes':>9} | {'ours':>10} {'dict':>10} {'rosbags':>10} "
        f"{'mcap-fast':>10} {'/rosbags':>8} {'/mcap':>7} {'/dict':>7} | "
        f"{'enc ours':>10} {'rosbags':>10} {'ratio':>7} {'same':>5}"
    )
    print(head)
    print("-" * len(head))
    reg = CodecRegistry()
    for label, name, data in class_cases():
        class_row(reg, label, name, data, seconds, rounds)
    print()


def _base64_bytes(value: Any) -> Any:
    """``uint8[]`` fields as rosbridge writes them: bytes (base64 in JSON)."""
    if isinstance(value, dict):
        return {k: _base64_bytes(v) for k, v in value.items()}
    if isinstance(value, list):
        return [_base64_bytes(v) for v in value]
    if isinstance(value, np.ndarray) and value.dtype == np.uint8:
        return value.tobytes()
    return value


def _convert_json(convert: Callable[[Any], object], text: bytes) -> object:
    import json

    return convert(json.loads(text))


def json_table(seconds: float, rounds: int) -> None:
    """JSON (as rosbridge sends it: ``uint8[]`` as base64 text) -> dict
    (``json.loads``, what a JSON message was before classes) against JSON ->
    instance (``json.loads`` then the registry's generated dict converter),
    per message of the class table."""
    import json

    from ros_mobile_bridge import jsonable

    clock = time.thread_time
    reg = CodecRegistry()
    print(
        f"JSON -> class (rosbridge's form): calls per second, best of {rounds} rounds "
        f"of {seconds:g} s CPU time each"
    )
    head = f"{'message':<17} {'bytes':>9} | {'-> dict':>10} {'-> class':>10} {'ratio':>7}"
    print(head)
    print("-" * len(head))
    for label, name, data in class_cases():
        message = reg.decoder(name, "cdr")(memoryview(reg.encoder(name, "cdr")(data)))
        text = json.dumps(jsonable(_base64_bytes(message.to_dict()))).encode()
        convert = reg.dict_converter(name)
        assert convert is not None
        assert convert(json.loads(text)) == message
        contenders: dict[str, Callable[[], object]] = {
            "dict": functools.partial(json.loads, text),
            "class": functools.partial(_convert_json, convert, text),
        }
        best: dict[str, float] = {}
        for _ in range(rounds):
            for what, func in contenders.items():
                best[what] = max(best.get(what, 0.0), rate(func, seconds, clock))
        print(
            f"{label:<17} {len(text):>9,} | {fmt_rate(best['dict']):>10} "
            f"{fmt_rate(best['class']):>10} {fmt_ratio(best['class'] / best['dict']):>7}"
        )
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=0.5, help="time per measurement")
    parser.add_argument(
        "--rounds", type=int, default=5, help="rounds of the class codec table (best of)"
    )
    parser.add_argument("--classes-only", action="store_true", help="only the class codec table")
    parser.add_argument("--json-only", action="store_true", help="only the JSON -> class table")
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
    if args.classes_only:
        class_table(min(seconds, 0.2), args.rounds)
        return
    if args.json_only:
        json_table(min(seconds, 0.2), args.rounds)
        return
    print(f"{seconds:g} s per measurement, best batch rate\n")
    for label, name, data in cases:
        bench_case(reg, label, name, data, seconds)
    class_table(min(seconds, 0.2), args.rounds)
    json_table(min(seconds, 0.2), args.rounds)


if __name__ == "__main__":
    main()
